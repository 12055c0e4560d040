"""``python -m haptic_bus ...`` is ``haptic-bus ...``: the console script's own entry
(:func:`haptic_bus.app.entry.main`), its exit status the process'."""

import sys

from haptic_bus.app.entry import main

sys.exit(main())
