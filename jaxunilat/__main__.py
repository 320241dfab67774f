"""`python -m jaxunilat`: the same command line as the `jaxunilat` script."""

import sys

from ._cli import main

if __name__ == "__main__":
    sys.exit(main())
