"""`python -m lidarjax.cli ...`: the same as the `lidarjax` command."""

import sys

from . import main

sys.exit(main())
