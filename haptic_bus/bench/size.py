"""How big a benchmark run is: ``smoke``, ``quick`` or ``full``.

``full`` (``haptic-bus bench``) measures what the README quotes; ``quick`` (``--quick``, what CI
runs) keeps every section and every comparison with fewer points, cycles and seconds; ``smoke``
(``--smoke``, what the test suite runs) keeps every section and the shape of every figure at
the smallest size that still produces it: its numbers show that the bench runs, not how fast
anything is.  Each section asks its own numbers with :meth:`Size.pick`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

T = TypeVar("T")


@dataclass(frozen=True)
class Size:
    """One of the three sizes of a run (module docstring)."""

    name: str

    def pick(self, smoke: T, quick: T, full: T) -> T:
        """The value for this size."""
        return {"smoke": smoke, "quick": quick, "full": full}[self.name]


SMOKE, QUICK, FULL = Size("smoke"), Size("quick"), Size("full")
