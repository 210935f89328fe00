"""``python -m voxgi.cli``: the ``voxgi`` command."""

import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
