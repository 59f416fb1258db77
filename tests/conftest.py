"""Test settings: property tests are derandomized by default, so that `make test` (and CI) is
reproducible; set HYPOTHESIS_PROFILE=explore to search with fresh random examples."""

import os

from hypothesis import settings

settings.register_profile("default", derandomize=True)
settings.register_profile("explore", derandomize=False, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


def local_client(n_workers: int):
    """A dask Client on a LocalCluster of ``n_workers`` single-threaded worker processes (for a
    module-scoped fixture: ``yield from local_client(2)``)."""
    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=":0")
    with Client(cluster) as c:
        yield c
    cluster.close()
