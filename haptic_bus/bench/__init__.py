"""``haptic-bus bench [--quick | --smoke] [--out DIR] [--soak [CYCLES]]``: run time against error, the bus against its limit.

One module per comparison (issues 6 and 14), each measured side by side in one run and quoted
as a ratio (absolute times are printed, never asserted); every timing is a median with its
min-max over at least 5 repeats (:mod:`~haptic_bus.bench.timing`):

1. :mod:`~haptic_bus.bench.passivity` -- passivity check: closed form, exact criterion, fixed
   theta grids 10^2..10^6, python-control; time per check vs error of the boundary against
   mpmath (:mod:`~haptic_bus.bench.mp_boundary`); a full check at delay 1 against one
   10^4-point numpy evaluation of ``T_fund``.
2. :mod:`~haptic_bus.bench.plant_sim` -- plant simulation in the closed loop: exact ZOH, Euler,
   RK4, solve_ivp; time per simulated second vs trajectory error against mpmath.
3. :mod:`~haptic_bus.bench.scene_cost` -- controller compute per cycle for 1..10 000 objects,
   compiled scene vs per-object loop.
4. :mod:`~haptic_bus.bench.loop_rate` -- closed-loop cycles/s in virtual time (lock-step bus,
   python-can's virtual bus, udp_multicast, Modbus TCP), the lock-step loop against
   python-can's threaded echo, and the hot path vs canopen's generic PDO path.
5. :mod:`~haptic_bus.bench.bus_limit` -- bits per cycle per axis, bus load, axes that fit.
6. :mod:`~haptic_bus.bench.thread_tuning` -- ``T = 1 ms`` with the real clock, two processes: lateness
   and the controller's share of a core in three set-ups, quiet and beside a CPU hog.
7. :mod:`~haptic_bus.bench.startup` -- ``check --json``, ``--help`` and (full run) ``profiles list`` against
   ``python -c "import numpy"``.
8. :mod:`~haptic_bus.bench.soak` -- cycles in virtual time (``--soak [CYCLES]``: 10^7; otherwise
   5 x 10^4 quick, 2 x 10^3 smoke, 10^6 full): the integer position sum exact, memory flat.
9. :mod:`~haptic_bus.bench.space_scene_cost` -- a scene in space (plane, boxes, spheres): seconds
   per ``force()`` call for 1..10 000 objects beside the 1-D scene's.
10. :mod:`~haptic_bus.bench.layer_cost` -- the passivity layer: the force it takes, nominal and
    adversarial timing.
11. :mod:`~haptic_bus.bench.preflight_runs` -- ``haptic-bus run cia402-handle`` against a fresh
    ``haptic-bus sim``, 20 times (5 quick, 1 smoke): how many pass pre-flight, and the loop delay judged.

Above the sections, issues 14 and 19's "Done when" (:mod:`~haptic_bus.bench.targets`): one row per
line with the measured figure, its spread, the target and PASS/FAIL, all from this one run (issue
19: the gate's verdict, the full check and the out-of-band exposure side by side against one numpy
``T_fund``, ``check --delay 1000``, ``check --json``).

Writes ``DIR/bench.json`` (every figure, the machine, versions, date), ``DIR/bench.md`` (the
tables, also printed) and PNG plots.  Three sizes (:mod:`~haptic_bus.bench.size`): the full run,
``--quick`` (what CI runs: every section, fewer points and shorter runs) and ``--smoke`` (what the
test suite runs: every section at its smallest, figures that only show the bench works); a
progress bar on stderr.  Ctrl-C ends the run: what finished is written and printed, one line on
stderr says where it stopped, exit 130.

Before any work: the packages of the ``[bench]`` extra (:data:`BENCH_EXTRA`) are there and the
output folder is writable, else one line on stderr and exit 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from haptic_bus.app.arguments import OneLineParser
from haptic_bus.bench.interrupts import Interrupts, SectionInterrupted, sigterm_as_sigint
from haptic_bus.bench.size import FULL, QUICK, SMOKE, Size
from haptic_bus.bench.timing import machine

if TYPE_CHECKING:  # the soak's module: only when it runs
    from haptic_bus.bench.soak import Tick

SECTIONS = ("passivity", "plant", "scene", "space", "loop", "bus", "realtime", "startup", "soak", "layer", "preflight")
# progress ticks each section makes (smoke, quick, full): for the bar's total
_TICKS = {"passivity": (5, 7, 17), "plant": (7, 15, 17), "scene": (5, 5, 5), "space": (5, 5, 5), "loop": (6, 6, 6),
          "bus": (2, 2, 2), "realtime": (3, 6, 6), "startup": (1, 3, 4), "soak": (10, 10, 10),
          "layer": (1, 9, 9), "preflight": (1, 5, 20)}
BENCH_EXTRA = {"control": "control"}  # import name -> distribution: pyproject's [bench] extra (mpmath is a runtime dependency)
SMOKE_SOAK_CYCLES = 2_000


class Progress:
    """A one-line progress bar on stderr (or nothing when disabled)."""

    def __init__(self, total: int, enabled: bool, width: int = 30) -> None:
        self.total, self.enabled, self.width = max(total, 1), enabled, width
        self.done = 0
        self.started = time.monotonic()

    def tick(self, label: str, *, advance: bool = True) -> None:
        """One step done (``advance`` False: none, the label a section's progress within its step); redraw."""
        self.done = min(self.done + (1 if advance else 0), self.total)
        if not self.enabled:
            return
        filled = round(self.width * self.done / self.total)
        bar = "#" * filled + "-" * (self.width - filled)
        elapsed = time.monotonic() - self.started
        sys.stderr.write(f"\r[{bar}] {self.done}/{self.total} {elapsed:5.0f} s  {label[:50]:<50}")
        sys.stderr.flush()

    def close(self, erase: bool = False) -> None:
        """End the bar's line (``erase``: blank it, so that the next line on stderr is the only one)."""
        if self.enabled:
            sys.stderr.write(f"\r{' ' * (self.width + 70)}\r" if erase else "\n")
            sys.stderr.flush()


def _runner(name: str) -> Callable[..., dict]:
    from importlib import import_module

    module = {"passivity": "passivity", "plant": "plant_sim", "scene": "scene_cost", "space": "space_scene_cost",
              "loop": "loop_rate",
              "bus": "bus_limit", "realtime": "thread_tuning", "startup": "startup", "layer": "layer_cost",
              "preflight": "preflight_runs"}[name]
    return import_module(f"haptic_bus.bench.{module}").run


def _soak_runner(cycles: int | None) -> Callable[..., dict]:
    def run(size: Size, tick: Tick) -> dict:
        from haptic_bus.bench.soak import FULL_CYCLES, QUICK_CYCLES
        from haptic_bus.bench.soak import run as soak

        return soak(cycles or size.pick(SMOKE_SOAK_CYCLES, QUICK_CYCLES, FULL_CYCLES), tick)

    return run


def missing_packages() -> list[str]:
    """The distributions of the ``[bench]`` extra that cannot be imported here (found, not imported: seconds)."""
    from importlib.util import find_spec

    return [distribution for module, distribution in BENCH_EXTRA.items() if find_spec(module) is None]


def run_bench(out_dir: str | Path, size: Size = FULL, progress: bool = False,
              sections: Sequence[str] = SECTIONS, soak: int | None = None) -> dict:
    """Run the benchmark sections at ``size`` (the soak of ``soak`` cycles, default by ``size``); write
    ``bench.json``, ``bench.md`` and PNGs into ``out_dir``.

    Returns the result dictionary (the content of ``bench.json``).  A section that cannot
    run (a missing optional package, a link that fails) is recorded with
    ``available: False`` and its reason, and the other sections still run.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    runners = {name: _soak_runner(soak) if name == "soak" else _runner(name) for name in dict.fromkeys(sections)}
    bar = Progress(sum(_TICKS[s][size.pick(0, 1, 2)] for s in runners), progress)
    started = time.perf_counter()
    flag = size.pick(" --smoke", " --quick", "")
    result: dict = {"command": "haptic-bus bench" + flag + (f" --soak {soak:.0e}" if soak else "")
                    + "".join(f" --only {s}" for s in runners if set(sections) != set(SECTIONS)),
                    "size": size.name, "quick": size is not FULL, "machine": machine(), "sections": {}}
    with Interrupts() as interrupts:

        def tick(label: str, *, advance: bool = True) -> None:
            bar.tick(label, advance=advance)
            interrupts.check()

        try:
            for name, runner in runners.items():
                t0 = time.perf_counter()
                try:
                    section = runner(size, tick)
                    section.setdefault("available", True)
                    interrupts.check()
                except KeyboardInterrupt as stop:  # Ctrl-C: what ran so far is still written
                    result["interrupted"] = name
                    if isinstance(stop, SectionInterrupted):  # and what of this section finished
                        result["sections"][name] = {**stop.section, "available": True,
                                                    "section_seconds": time.perf_counter() - t0}
                    break
                except Exception as exc:
                    section = {"available": False, "reason": f"{type(exc).__name__}: {exc}",
                               "traceback": traceback.format_exc(limit=6)}
                section["section_seconds"] = time.perf_counter() - t0
                result["sections"][name] = section
        finally:
            bar.close(erase="interrupted" in result)
    result["total_seconds"] = time.perf_counter() - started
    from haptic_bus.bench.report import markdown, plots
    from haptic_bus.bench.targets import done_when, issue_19, issue_26

    result["done_when"] = done_when(result["sections"])
    result["done_when_19"] = issue_19(result["sections"])
    result["done_when_26"] = issue_26(result["sections"])

    (out / "bench.json").write_text(json.dumps(result, indent=1, default=_json_default, allow_nan=True) + "\n")
    (out / "bench.md").write_text(markdown(result))
    result["plots"] = [str(p) for p in plots(result, out)]
    return result


def _json_default(value):
    if hasattr(value, "item"):  # numpy scalars
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return str(value)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``haptic-bus bench``."""
    parser = OneLineParser(prog="haptic-bus bench", description=__doc__.split("\n\n")[0])
    sizes = parser.add_mutually_exclusive_group()
    sizes.add_argument("--quick", action="store_const", dest="size", const=QUICK, default=FULL,
                       help="the short run CI uses: every section, fewer points, shorter runs")
    sizes.add_argument("--smoke", action="store_const", dest="size", const=SMOKE,
                       help="every section at its smallest, seconds: the figures only show that the bench runs")
    parser.add_argument("--out", default="bench-out", help="output folder (default: ./bench-out)")
    parser.add_argument("--only", action="append", choices=SECTIONS, help="run only this section (repeatable)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.add_argument("--soak", type=_cycles, nargs="?", const=10_000_000, metavar="CYCLES",
                        help="the soak's cycles in virtual time (exact position sum, flat memory): CYCLES, 10^7 "
                             "without a number; default 5e4 with --quick, 2e3 with --smoke, else 10^6")
    return parser


def _cycles(text: str) -> int:
    """``--soak``'s cycles: a whole number 1..1e9, written as an integer or as 1e6 (``inf`` was an
    OverflowError's traceback, ``1.5`` taken as 1)."""
    from haptic_bus.errors import ParameterError

    invalid = ParameterError("soak cycles", text, "a whole number of cycles 1..1e9 (e.g. 1e6)")
    try:
        value = float(text)
    except ValueError:
        raise invalid from None
    if not (math.isfinite(value) and value.is_integer() and 1 <= value <= 10**9):
        raise invalid
    return int(value)


def _refusal(args: argparse.Namespace) -> str | None:
    """Why the bench cannot start (a missing package of the [bench] extra, an unwritable --out), or None."""
    from haptic_bus.errors import ParameterError
    from haptic_bus.validation import writable_folder

    missing = missing_packages()
    if missing:
        return (f"the [bench] extra is missing: {', '.join(missing)}; install it with: pip install 'haptic_bus[bench]' "
                "(from a checkout: pip install -e '.[bench]')")
    try:
        writable_folder("--out", args.out)  # the line says "haptic-bus bench" already
    except ParameterError as error:
        return str(error)
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``haptic-bus bench``; print the tables; exit 0 (2 for bad arguments, a missing package
    of the [bench] extra or an unwritable --out, each one line on stderr)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    refusal = _refusal(args)
    if refusal is not None:
        print(f"haptic-bus bench: error: {refusal}", file=sys.stderr)
        return 2
    with sigterm_as_sigint() as terminated:
        try:
            result = run_bench(args.out, size=args.size, progress=not args.no_progress,
                               sections=args.only or SECTIONS, soak=args.soak)
            print((Path(args.out) / "bench.md").read_text())
            print(f"wrote {Path(args.out) / 'bench.json'}, {Path(args.out) / 'bench.md'}"
                  + "".join(f", {p}" for p in result["plots"]))
        except KeyboardInterrupt:  # outside a section (starting, writing): nothing more to show
            print(f"haptic-bus bench: interrupted{' (SIGTERM)' if terminated else ''}", file=sys.stderr)
            return 130
    if "interrupted" in result:  # Ctrl-C or SIGTERM: a bench cut short is no result, though what it has is kept
        print(f"haptic-bus bench: interrupted{' (SIGTERM)' if terminated else ''} in section {result['interrupted']}; "
              "bench.json holds the sections before it", file=sys.stderr)
        return 130
    return 0

if __name__ == "__main__":
    sys.exit(main())
