"""The paper's Fig. 2 (partial slip of a tilted ellipsoid): a thin wrapper around the bundled
script ``thirdbody/examples/fig2_partial_slip.py`` (``thirdbody examples copy fig2 DIR``)."""

import sys

from thirdbody.examples.fig2_partial_slip import main

__all__ = ["main"]

if __name__ == "__main__":
    main(sys.argv[1:])
