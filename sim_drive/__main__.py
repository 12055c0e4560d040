"""``python -m sim_drive ...`` is ``haptic-bus sim ...``."""

import sys

from sim_drive.cli import main

sys.exit(main())
