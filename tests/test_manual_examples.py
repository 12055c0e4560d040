"""The manual's examples (``docs/*.md``) run here as the pages show them: every Python block (the drive
loop's documented bus the one substitution: this test's own simulated drive), and the console blocks
whose output does not depend on the machine, typed into bash from a folder that holds the repository's
``profiles`` and ``tests`` as the pages' "from the repository's root" asks, their output compared line
for line.

The console walk-through of ``docs/commissioning.md`` runs in ``tests/test_commissioning_walkthrough.py``.
The rest are recorded sessions whose path a test of its own drives as real processes (``RECORDED``);
every ``haptic-bus`` command line of every page is parsed by its own parser in ``tests/test_readme.py``.
"""

from __future__ import annotations

import pathlib
import signal
import subprocess
import time

import pytest

from tests.console import Shell, console_commands, user_env
from tests.doc_blocks import PAGES, REPO, code_blocks

DOCS = REPO / "docs"
DOCUMENTED_DRIVE_BUS = 'interface="udp_multicast", channel="239.74.163.2", bus_kwargs={"port": 43113}'


RUN_HERE = {("profiles.md", 0), ("foreign-drive.md", 0)}  # (page, console block): the tests at the end of this file
WALKTHROUGH = {("commissioning.md", i) for i in range(5)}  # tests/test_commissioning_walkthrough.py
RECORDED = {  # sessions after a kill -9 of a real-time run, or of several axes across processes: the tests that drive them
    ("operations.md", "console", 0): "tests/test_operations_e2e.py",
    ("operations.md", "console", 1): "tests/test_operations_e2e.py",
    ("operations.md", "json", 0): "tests/test_operations_e2e.py",
    ("controller.md", "bash", 0): "tests/test_run_plots.py",
    ("axes.md", "bash", 0): "tests/test_axes_run.py",
}


def _example(page: str, index: int = 0) -> str:
    return code_blocks(DOCS / page, "python")[index]


def _run(code: str, page: str) -> dict[str, object]:
    namespace: dict[str, object] = {"__name__": f"docs.{page}"}
    exec(compile(code, str(DOCS / page), "exec"), namespace)
    return namespace


def test_every_python_example_of_the_manual_has_its_test_here() -> None:
    found = {(path.name, i) for path in PAGES for i, _ in enumerate(code_blocks(path, "python"))}
    assert found == {("errors.md", 0), ("python-api.md", 0), ("axes.md", 0)}  # the three tests below


def test_every_other_block_of_the_manual_is_run_here_or_by_a_test_it_names() -> None:
    """A console block either runs here or in the walk-through; a recorded one names the test that drives
    its path, and that test exists."""
    consoles = {(path.name, i) for path in PAGES for i, _ in enumerate(code_blocks(path, "console"))}
    assert consoles == RUN_HERE | WALKTHROUGH | {(page, i) for page, kind, i in RECORDED if kind == "console"}
    others = {(path.name, kind, i) for path in PAGES for kind in ("bash", "json", "toml")
              for i, _ in enumerate(code_blocks(path, kind))}
    assert others == {key for key in RECORDED if key[1] != "console"}
    for (page, _, _), test in RECORDED.items():
        assert (REPO / test).is_file() and test in (DOCS / page).read_text(), (page, test)


def _from_the_root(tmp_path: pathlib.Path) -> pathlib.Path:
    """An empty folder that reads like the repository's root: its profiles and tests, linked."""
    for name in ("profiles", "tests"):
        (tmp_path / name).symlink_to(REPO / name)
    return tmp_path


def test_both_readers_refuse_a_bad_profile_with_the_same_line(tmp_path: pathlib.Path) -> None:
    commands = console_commands("```console\n" + code_blocks(DOCS / "profiles.md", "console")[0] + "```")
    assert len(commands) == 3
    shell = Shell(_from_the_root(tmp_path))
    try:
        for command, status in zip(commands, (0, 2, 2), strict=True):
            assert shell.type(command.text, 120) == (status, command.shown + "\n" if command.shown else ""), command.text
    finally:
        shell.close()


def test_the_simulator_behind_a_vendors_eds_logs_what_the_eds_lacks(tmp_path: pathlib.Path) -> None:
    """The page's lines are the simulator's first; it then serves until SIGTERM, which it exits on with 0."""
    [command] = console_commands("```console\n" + code_blocks(DOCS / "foreign-drive.md", "console")[0] + "```")
    shown = command.shown.splitlines()
    process = subprocess.Popen(["bash", "-c", f"exec {command.text}"], cwd=_from_the_root(tmp_path), env=user_env(),
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert process.stdout is not None
    try:
        deadline = time.monotonic() + 120  # s of wall clock: the imports, on a loaded machine
        lines = []
        while len(lines) < len(shown) and time.monotonic() < deadline:
            lines.append(process.stdout.readline().rstrip("\n"))
        assert lines == shown
    finally:
        process.send_signal(signal.SIGTERM)
        status = process.wait(30)
        process.stdout.close()
    assert status == 0


def test_the_errors_page_catches_both_roots_in_one_clause() -> None:
    from haptic_bus.errors import ALL_ERRORS

    namespace = _run(_example("errors.md"), "errors.md")
    assert namespace["ALL_ERRORS"] is ALL_ERRORS  # the block's body is `...`: it runs, catching nothing


def test_the_drive_loop_of_the_python_api_page_runs_against_the_simulated_drive(haptic_sim) -> None:
    """1000 cycles of the page's 2 N s/m damper against the simulated drive in this process (the lock-step
    bus), whose hand pushes a constant 3 N on a handle of m = 1 kg, b = 20 N s/m.  The handle
    settles at v = 3 / (20 + 2) m/s: its time constant m / 22 = 45 ms is 1/22 of the loop's second
    (transient e^-22), and the damper's force is sent in whole per mille of torque (one per mille is
    0.32 N m x 50 / 1000 = 16 mN), so v is within 8 mN / 22 N s/m = 0.36 mm/s of it, plus one
    0x606C count (1 um/s)."""
    code = _example("python-api.md")
    assert code.count(DOCUMENTED_DRIVE_BUS) == 1
    push = {"model": "constant", "level": 3.0}
    drive = haptic_sim("cia402-handle", interface="lockstep", mass=1.0, friction=20.0, operator=push)
    bus = dict(drive.bus)
    interface, channel = bus.pop("interface"), bus.pop("channel")
    spelled = f"interface={interface!r}, channel={channel!r}, bus_kwargs={bus!r}"
    namespace = _run(code.replace(DOCUMENTED_DRIVE_BUS, spelled), "python-api.md")
    master, scaling = namespace["drive"], namespace["scaling"]
    assert master.stats.syncs_sent >= 1000
    assert master.stats.saturated_outputs == 0  # 3 N of damper force is 188 per mille, below the 500 asked
    velocity = namespace["inputs"].velocity * scaling.velocity_per_count
    permille_force = 0.32 * 50.0 / 1000.0
    assert velocity == pytest.approx(3.0 / 22.0, abs=permille_force / 2 / 22.0 + 1e-6)


def test_the_coupled_gate_example_agrees_with_its_own_limit() -> None:
    """The oblique wall K = 1500 N/m, B = 10 N s/m along (1, 1, 1) is passive exactly when 1500 N/m
    lies within the passive K the limits find along that direction at B = 10 (their ends are exact to
    1e-9 relative, far inside the distance of 1500 from either end)."""
    namespace = _run(_example("axes.md"), "axes.md")
    verdict = namespace["verdict"]
    largest = namespace["passive_along"](namespace["axes"], [1, 1, 1], K=0.0, B=10.0, which="K").largest
    assert verdict.passive == (1500.0 <= largest)
    assert (verdict.margin >= 0) == verdict.passive
    assert abs(1500.0 - largest) > 1e-6 * largest  # the verdict is not decided at a boundary's round-off
