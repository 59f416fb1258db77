"""Test settings: property tests are derandomized by default, so that `make test` (and CI) is
reproducible; set HYPOTHESIS_PROFILE=explore to search with fresh random examples."""

import os

# One BLAS thread per process, set before numpy is first imported (xdist's workers, the runs the
# tests start in subprocesses and dask's workers inherit it). The suite runs in 2 processes on 2
# cores: OpenBLAS's own threads (as many as cores, in each process) then contend with the other
# process and spin while they wait, which made the small dense solves of the Spence reference
# about 7 times slower (200 rings: 37 s against 5.5 s on this machine).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from hypothesis import settings  # noqa: E402

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
