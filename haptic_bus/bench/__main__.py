"""``python -m haptic_bus.bench [--quick | --smoke] [--out DIR]``: the same as ``haptic-bus bench``."""

import sys

from haptic_bus.bench import main

sys.exit(main())
