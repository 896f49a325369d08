"""`python -m ptzd` is the same as the `ptzd` console script."""

import sys

from ptzd.cli import main

sys.exit(main())
