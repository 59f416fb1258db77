"""``python -m thirdbody``: the command line (the same as the ``thirdbody`` command)."""

from .cli import main

if __name__ == "__main__":
    main()
