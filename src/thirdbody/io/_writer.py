"""The process that writes a run's results while the run goes on: ``python -m
thirdbody.io._writer``, started by :func:`thirdbody.io.run_to_file` with ``background`` (see
``thirdbody.io.results._BackgroundWriter``). It reads the steps from stdin and reports on
stdout."""

import os
import signal
import sys

if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)    # the run decides when it ends
    replies = os.dup(1)                              # stdout is for the report alone: whatever
    os.dup2(2, 1)                                    # else prints goes to stderr

    from thirdbody.io.results import serve

    serve(0, replies)
    sys.stderr.flush()
    os._exit(0)         # at once: the run waits for this exit, not for the interpreter's teardown
