"""``python -m etobs``: the command line."""

import sys

from etobs.cli.main import main

sys.exit(main())
