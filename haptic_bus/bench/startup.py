"""Benchmark 7: how long the command line takes to start, against ``python -c "import numpy"``.

Each command runs as a fresh process (the installed ``haptic-bus`` script beside this Python,
else ``python -m haptic_bus``), alternating with ``python -c "import numpy"`` so that
each pair gives one ratio; wall time from ``Popen`` to exit.  Issue 14's target: ``check
--json``, ``profiles list`` and ``--help`` within 2.5 x the numpy import; issue 19's: ``check --delay 1000``
(the text report, out-of-band exposure included) within 0.5 s on an idle machine (its wall time is
reported with the load average beside it).  Beside it, the
modules that cost ``haptic-bus check`` the most import time (``python -X importtime``, one run,
numpy's own modules left out: numpy is the yardstick), and which of the modules ``check`` has no
use for it imports (:data:`FORBIDDEN`: scipy.optimize, matplotlib, canopen, pymodbus), each with
the chain of modules that imported it.
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

from haptic_bus.bench.size import Size
from haptic_bus.bench.timing import REPEATS, paired

RATIO_TARGET = 2.5
CHECK_ARGS = ("check", "--mass", "0.5", "--friction", "0.1", "--period", "1e-3", "--stiffness", "200",
              "--damping", "100", "--delay", "1", "--json")
LONG_DELAY_ARGS = ("check", "--mass", "0.5", "--friction", "1", "--period", "1e-3", "--stiffness", "0.5",
                   "--damping", "0", "--delay", "1000")
LONG_DELAY_TARGET_S = 0.5  # issue 19: check --delay 1000 (text, out-of-band exposure included) on an idle machine
COMMANDS = {"check --json": CHECK_ARGS, "profiles list": ("profiles", "list"), "--help": ("--help",),
            "check --delay 1000": LONG_DELAY_ARGS}
SMOKE_COMMANDS = ("check --json",)  # the one issue 14 sets a target for
QUICK_COMMANDS = ("check --json", "--help", "check --delay 1000")  # profiles list judges every shipped profile: seconds a launch
NUMPY = (sys.executable, "-c", "import numpy")
FORBIDDEN = ("scipy.optimize", "matplotlib", "canopen", "pymodbus")  # nothing check --json needs


def _load() -> list[float] | None:
    try:
        return list(os.getloadavg())
    except OSError:
        return None


def haptic_bus_command() -> list[str]:
    """How a user starts ``haptic-bus``: the console script beside this interpreter (not a shim)."""
    script = shutil.which("haptic-bus", path=str(Path(sys.executable).parent))
    return [script] if script else [sys.executable, "-m", "haptic_bus"]


def wall_time(command: tuple[str, ...] | list[str]) -> float:
    """Seconds from start to exit of ``command`` (output discarded)."""
    start = time.perf_counter()
    subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False, env=_environment())
    return time.perf_counter() - start


def _environment() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONPROFILEIMPORTTIME", None)
    return env


ImportLine = tuple[float, float, int, str]  # own s, cumulative s, nesting depth, module


def import_lines(command: list[str]) -> list[ImportLine]:
    """``python -X importtime``'s lines when ``command`` runs (an importer comes after what it imported)."""
    env = _environment()
    env["PYTHONPROFILEIMPORTTIME"] = "1"
    result = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=False, env=env)
    lines: list[ImportLine] = []
    for line in result.stderr.splitlines():
        parts = line.removeprefix("import time:").split("|")
        if len(parts) != 3 or not parts[0].strip().isdigit():
            continue
        name = parts[2].rstrip()
        depth = (len(name) - len(name.lstrip())) // 2
        lines.append((int(parts[0]) * 1e-6, int(parts[1]) * 1e-6, depth, name.strip()))
    return lines


def import_costs(lines: list[ImportLine], top: int = 8) -> list[dict]:
    """The ``top`` modules by own import time (s), numpy's left out."""
    kept = sorted((line for line in lines if line[3].split(".")[0] != "numpy"), key=lambda line: line[0], reverse=True)
    return [{"module": name, "self_s": own, "cumulative_s": total} for own, total, _, name in kept[:top]]


def heavy_imports(lines: list[ImportLine], forbidden: tuple[str, ...] = FORBIDDEN) -> dict:
    """Which of ``forbidden`` were imported, each with its importers (nearest first)."""
    chains: dict[str, list[str]] = {}
    for i, (_, _, depth, name) in enumerate(lines):
        if name not in forbidden:
            continue
        chain = []
        for _, _, outer, importer in lines[i + 1:]:
            if outer < depth:
                chain.append(importer)
                depth = outer
        chains[name] = chain
    return {"forbidden": list(forbidden), "imported": [m for m in forbidden if m in chains], "chains": chains}


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 7; returns its section of ``bench.json``."""
    repeats = size.pick(REPEATS, REPEATS, 2 * REPEATS + 1)
    commands = {label: COMMANDS[label] for label in size.pick(SMOKE_COMMANDS, QUICK_COMMANDS, tuple(COMMANDS))}
    base = haptic_bus_command()
    rows = {}
    lines = import_lines([*base, *CHECK_ARGS])  # also warms the page cache for numpy and for check --json
    for label, args in commands.items():
        command = [*base, *args]
        if args != CHECK_ARGS:  # warm the page cache for this command
            wall_time(command)
        own, numpy, ratio = paired(functools.partial(wall_time, command), functools.partial(wall_time, NUMPY), repeats)
        rows[label] = {"command": " ".join(command), "wall_s": own.to_dict(), "numpy_import_s": numpy.to_dict(),
                       "ratio": ratio.to_dict(), "met": ratio.median <= RATIO_TARGET}
        tick(f"startup: {label}")
    return {
        "description": "wall time of a fresh haptic-bus process against python -c 'import numpy', pairwise",
        "ratio_target": RATIO_TARGET,
        "long_delay_target_s": LONG_DELAY_TARGET_S,
        "load_average": _load(),
        "commands": rows,
        "check_import_costs": import_costs(lines),
        "check_heavy_imports": heavy_imports(lines),
    }
