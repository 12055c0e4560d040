"""Values as strict JSON writes them: what ``run.json`` and the ``--json`` outputs print.

JSON has no NaN or infinity (Python's ``json`` writes bare ``NaN`` tokens other readers refuse),
no tuples and only string keys: :func:`json_ready` turns a value built of dicts, lists, tuples
and scalars into one that ``json.dumps(..., allow_nan=False)`` accepts.  A module of its own so
that a command printing JSON imports nothing of a run's.
"""

from __future__ import annotations

import math
from typing import Any


def json_ready(value: Any) -> Any:
    """``value`` as JSON without NaN/inf: non-finite floats as strings, tuples as lists, keys as strings."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    return value
