"""``python -m popdispatch.cli``."""

import sys

from popdispatch.cli.process import main

if __name__ == "__main__":
    sys.exit(main())
