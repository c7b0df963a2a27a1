"""``python -m popdispatch.cli``."""

import sys

from popdispatch.cli.process import main

sys.exit(main())
