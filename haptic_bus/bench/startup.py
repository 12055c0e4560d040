"""Benchmark 7: how long the command line takes to start, against ``python -c "import numpy"``.

Each command runs as a fresh process (the installed ``haptic-bus`` script beside this Python,
else ``python -m haptic_bus.app.cli``), alternating with ``python -c "import numpy"`` so that
each pair gives one ratio; wall time from ``Popen`` to exit.  Issue 14's target: ``check
--json``, ``profiles list`` and ``--help`` within 2.5 x the numpy import.  Beside it, the
modules that cost ``haptic-bus check`` the most import time (``python -X importtime``, one run,
numpy's own modules left out: numpy is the yardstick).
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from haptic_bus.bench.timing import REPEATS, paired

RATIO_TARGET = 2.5
CHECK_ARGS = ("check", "--mass", "0.5", "--friction", "0.1", "--period", "1e-3", "--stiffness", "200",
              "--damping", "100", "--delay", "1", "--json")
COMMANDS = {"check --json": CHECK_ARGS, "profiles list": ("profiles", "list"), "--help": ("--help",)}
NUMPY = (sys.executable, "-c", "import numpy")


def haptic_bus_command() -> list[str]:
    """How a user starts ``haptic-bus``: the console script beside this interpreter (not a shim)."""
    script = shutil.which("haptic-bus", path=str(Path(sys.executable).parent))
    return [script] if script else [sys.executable, "-m", "haptic_bus.app.cli"]


def wall_time(command: tuple[str, ...] | list[str]) -> float:
    """Seconds from start to exit of ``command`` (output discarded)."""
    start = time.perf_counter()
    subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False, env=_environment())
    return time.perf_counter() - start


def _environment() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONPROFILEIMPORTTIME", None)
    return env


def import_costs(command: list[str], top: int = 8) -> list[dict]:
    """The ``top`` modules by own import time (s) when ``command`` runs, numpy's left out."""
    env = _environment()
    env["PYTHONPROFILEIMPORTTIME"] = "1"
    result = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=False, env=env)
    rows: list[dict[str, Any]] = []
    for line in result.stderr.splitlines():
        parts = line.removeprefix("import time:").split("|")
        if len(parts) != 3 or not parts[0].strip().isdigit():
            continue
        name = parts[2].strip()
        if name.split(".")[0] != "numpy":
            rows.append({"module": name, "self_s": int(parts[0]) * 1e-6, "cumulative_s": int(parts[1]) * 1e-6})
    return sorted(rows, key=lambda r: float(r["self_s"]), reverse=True)[:top]


def run(quick: bool, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 7; returns its section of ``bench.json``."""
    repeats = REPEATS if quick else 2 * REPEATS + 1
    base = haptic_bus_command()
    wall_time(NUMPY)  # warm the page cache for both sides
    rows = {}
    for label, args in COMMANDS.items():
        command = [*base, *args]
        wall_time(command)
        own, numpy, ratio = paired(functools.partial(wall_time, command), functools.partial(wall_time, NUMPY), repeats)
        rows[label] = {"command": " ".join(command), "wall_s": own.to_dict(), "numpy_import_s": numpy.to_dict(),
                       "ratio": ratio.to_dict(), "met": ratio.median <= RATIO_TARGET}
        tick(f"startup: {label}")
    return {
        "description": "wall time of a fresh haptic-bus process against python -c 'import numpy', pairwise",
        "ratio_target": RATIO_TARGET,
        "commands": rows,
        "check_import_costs": import_costs([*base, *CHECK_ARGS]),
    }
