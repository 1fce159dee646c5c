"""``python -m wristtrack.cli``."""

import sys

from wristtrack.cli import main

sys.exit(main())
