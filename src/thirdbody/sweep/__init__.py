"""Parameter sweeps: the Cartesian product of configuration values, run on dask.distributed.

A sweep file (TOML) names a base configuration and the axes to vary::

    base = "fig4a"                  # a config file (relative to this file) or a bundled example

    [axes]                          # any configuration key, dotted; a list or a range
    "plates.mu" = [0.2, 0.3, 0.4]   # plates.mu sets both plates (mu_up = mu_low)
    "particle.orientation_deg" = {start = -60, stop = 60, num = 5}     # inclusive linspace
    "particle.seed" = {start = 1, stop = 4, step = 1}                  # inclusive range

    [set]                           # optional: keys overridden on every case
    "load.steps" = 15
    "numerics.maps_every" = 0

Every case is checked like a configuration file before anything runs (:class:`SweepError` names
the case and the key). A case is identified by the hash of its resolved configuration and writes
``OUT/cases/<hash>.nc`` (the inputs, the resolved configuration and the sweep values are stored
in its attributes). Rerunning a sweep skips the cases already finished, resumes the ones a
killed worker left half done, and retries the ones that raised. A case that raises records its
traceback in ``OUT/cases/<hash>.error.txt``; the others go on. At the end the per-case
summaries, and the per-step scalars when every case has the same number of steps, are combined
along the sweep axes into ``OUT/summary.nc`` (and ``OUT/summary.csv``, one row per case), and
``OUT/state_map.png`` shows the behaviour and the total rotation over the first two axes.

The cases run as tasks on a :class:`dask.distributed.Client`: by default a ``LocalCluster`` of
single-threaded worker processes on this machine, or any existing cluster (``scheduler`` address).
Workers of a remote cluster need thirdbody installed and must see ``OUT`` (a shared file
system). A worker that dies has its task rescheduled by dask (up to
``distributed.scheduler.allowed-failures`` times, 3 by default); the new attempt resumes from
the steps the dead one wrote.
"""

from ..schema import BEHAVIOURS, STATES
from .cases import UnreadableCase, _case_status, _CaseData  # noqa: F401 (the CLI, tests)
from .run import LOCAL_WORKER_CONFIG, SweepReport, _dask_client, run_case, run_sweep  # noqa: F401
from .spec import Axis, Case, Sweep, SweepError, case_id, load_sweep, parse_sweep
from .summary import _case_summary, summarize  # noqa: F401

__all__ = [
    "BEHAVIOURS",
    "LOCAL_WORKER_CONFIG",
    "STATES",
    "Axis",
    "Case",
    "Sweep",
    "SweepError",
    "SweepReport",
    "UnreadableCase",
    "case_id",
    "load_sweep",
    "parse_sweep",
    "run_case",
    "run_sweep",
    "summarize",
]
