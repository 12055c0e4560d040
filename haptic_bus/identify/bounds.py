"""What an identification accepts and does by default (a module without numerical imports, so
that the command line can state these bounds without loading scipy)."""

from __future__ import annotations

DURATION_RANGE = (1.0, 600.0)  # s of excitation
TRAVEL_RANGE = (1e-6, 10.0)  # m either side of the start
DEFAULT_DURATION = 20.0  # s of excitation
DEFAULT_TRAVEL = 0.01  # m either side of the start
MAX_DELAY = 4  # whole samples searched by default: D in [0, MAX_DELAY + 1]
DELAY_SEARCH_RANGE = (0, 50)  # whole samples: the largest search a run may ask for
