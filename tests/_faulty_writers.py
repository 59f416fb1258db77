"""Results writers with faults, for tests/test_results_background.py: the writing child process
unpickles them by name, so they live in a module it can import (``tests`` on PYTHONPATH)."""

import time

from thirdbody.io import results


class SlowWriter(results._StepWriter):
    """Takes 0.3 s more per step: the child lags and the steps wait in the pipe."""

    def save(self, sim, blob):
        time.sleep(0.3)
        super().save(sim, blob)


class FullDiskWriter(results._StepWriter):
    """The disk fills up while appending step 2."""

    def _append(self, sim, *args):
        if len(sim.records) == 3:
            raise OSError(28, "No space left on device")
        return super()._append(sim, *args)


class GatedWriter(results._StepWriter):
    """Saves nothing until the file named by $THIRDBODY_TEST_GATE exists."""

    def save(self, sim, blob):
        import os

        while not os.path.exists(os.environ["THIRDBODY_TEST_GATE"]):
            time.sleep(0.01)
        super().save(sim, blob)


class LateWriter(results._StepWriter):
    """Received (unpickled) by the child only once the file named by $THIRDBODY_TEST_GATE
    exists: the child is not ready until then."""

    def __setstate__(self, state):
        import os

        while not os.path.exists(os.environ["THIRDBODY_TEST_GATE"]):
            time.sleep(0.01)
        self.__dict__.update(state)
