"""``python -m thirdbody.cli``: the command line (as ``thirdbody`` and ``python -m thirdbody``)."""

from . import main

if __name__ == "__main__":
    main()
