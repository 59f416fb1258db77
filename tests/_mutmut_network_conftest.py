"""Appended to tests/conftest.py in the scratch copy of `make mutation-network` (never imported
by the suite itself): mutmut runs a mutant's tests with ``-x`` in the order it lists them (a
set's order), so a mutant that the one-second contact-model tests kill would first wait for
the cluster solves. The contact-model tests and the solver's checks on made-up states run
first, then the cluster tests, the heaviest last."""

_FAST = ("test_network_stiffness", "test_network_cluster_checks")
_HEAVY = ("learn_from_it", "without_the_first_phase", "sticking_ellipsoid", "turning_ellipsoid")


def pytest_collection_modifyitems(session, config, items):
    def cost(item):
        return (not any(name in item.nodeid for name in _FAST),
                any(name in item.nodeid for name in _HEAVY))

    items.sort(key=cost)
