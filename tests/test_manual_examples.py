"""Every Python example of the manual (``docs/*.md``) runs here as the page shows it, the documented bus
of the drive loop the one substitution (this test's own simulated drive).

The console walk-through of ``docs/commissioning.md`` runs in ``tests/test_commissioning_walkthrough.py``;
every ``haptic-bus`` command line the pages show is parsed by its own parser in ``tests/test_readme.py``.
"""

from __future__ import annotations

import pytest

from tests.doc_blocks import PAGES, REPO, code_blocks

DOCS = REPO / "docs"
DOCUMENTED_DRIVE_BUS = 'interface="udp_multicast", channel="239.74.163.2", bus_kwargs={"port": 43113}'


def _example(page: str, index: int = 0) -> str:
    return code_blocks(DOCS / page, "python")[index]


def _run(code: str, page: str) -> dict[str, object]:
    namespace: dict[str, object] = {"__name__": f"docs.{page}"}
    exec(compile(code, str(DOCS / page), "exec"), namespace)
    return namespace


def test_every_python_example_of_the_manual_has_its_test_here() -> None:
    found = {(path.name, i) for path in PAGES for i, _ in enumerate(code_blocks(path, "python"))}
    assert found == {("errors.md", 0), ("python-api.md", 0), ("axes.md", 0)}  # the three tests below


def test_the_errors_page_catches_both_roots_in_one_clause() -> None:
    from haptic_bus.errors import ALL_ERRORS

    namespace = _run(_example("errors.md"), "errors.md")
    assert namespace["ALL_ERRORS"] is ALL_ERRORS  # the block's body is `...`: it runs, catching nothing


def test_the_drive_loop_of_the_python_api_page_runs_against_the_simulated_drive(haptic_sim) -> None:
    """1000 cycles of the page's 2 N s/m damper against the simulated drive in this process (python-can's
    virtual bus), whose hand pushes a constant 3 N on a handle of m = 1 kg, b = 20 N s/m.  The handle
    settles at v = 3 / (20 + 2) m/s: its time constant m / 22 = 45 ms is 1/22 of the loop's second
    (transient e^-22), and the damper's force is sent in whole per mille of torque (one per mille is
    0.32 N m x 50 / 1000 = 16 mN), so v is within 8 mN / 22 N s/m = 0.36 mm/s of it, plus one
    0x606C count (1 um/s)."""
    code = _example("python-api.md")
    assert code.count(DOCUMENTED_DRIVE_BUS) == 1
    drive = haptic_sim("cia402-handle", mass=1.0, friction=20.0, operator={"model": "constant", "level": 3.0})
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
