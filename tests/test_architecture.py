"""The dependency direction DESIGN.md section 2 draws, read off the import graph of the source.

drives <- haptic_bus base (errors, validation) <- analysis <- control <- app/bench;
sim_drive uses drives and haptic_bus' analysis (the plant) and base, never the controller;
haptic_bus reaches sim_drive only through ``haptic_bus.app.rig``.  Every import statement is
counted, including the ones inside functions (a lazy import is still a dependency).
"""

from __future__ import annotations

import ast
import json
import pathlib
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("haptic_bus", "drives", "sim_drive")
BUS_LIBRARIES = ("can", "canopen", "pymodbus")


def _module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: pathlib.Path) -> set[str]:
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return found


def _graph() -> dict[str, set[str]]:
    graph = {}
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            graph[_module_name(path)] = _imports(path)
    return graph


GRAPH = _graph()


def _within(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def _offenders(modules: str, forbidden: tuple[str, ...], allowed: tuple[str, ...] = ()) -> list[str]:
    return sorted(
        f"{module} imports {target}"
        for module, targets in GRAPH.items() if _within(module, modules)
        for target in targets
        if any(_within(target, f) for f in forbidden) and not any(_within(target, a) for a in allowed)
    )


def test_the_graph_covers_every_package():
    assert {m.split(".")[0] for m in GRAPH} == set(PACKAGES)
    assert "drives.canopen.drive" in GRAPH and "haptic_bus.analysis.criterion" in GRAPH


def test_drives_import_nothing_of_ours_above_them():
    assert _offenders("drives", ("haptic_bus", "sim_drive")) == []


def test_sim_drive_uses_only_the_analysis_and_the_base_of_haptic_bus():
    allowed = ("haptic_bus.analysis", "haptic_bus.profile", "haptic_bus.validation", "haptic_bus.errors",
               "haptic_bus.console", "haptic_bus._version")  # a constant
    assert _offenders("sim_drive", ("haptic_bus",), allowed) == []


def test_haptic_bus_reaches_the_simulator_only_through_the_rig():
    offenders = [o for o in _offenders("haptic_bus", ("sim_drive",)) if not o.startswith("haptic_bus.app.rig ")]
    assert offenders == []


def test_the_analysis_imports_no_bus_code_and_nothing_above_it():
    forbidden = (*BUS_LIBRARIES, "haptic_bus.control", "haptic_bus.app", "haptic_bus.bench", "sim_drive")
    assert _offenders("haptic_bus.analysis", forbidden) == []
    assert _offenders("haptic_bus.analysis", ("drives",), ("drives.errors",)) == []


def test_the_base_sits_at_the_bottom():
    for base in ("haptic_bus.errors", "haptic_bus.validation", "haptic_bus.console"):
        assert _offenders(base, ("haptic_bus", "sim_drive"), ("haptic_bus.errors",)) == []
        assert _offenders(base, ("drives",), ("drives.errors",)) == []


def test_the_profile_schema_sits_below_the_controller():
    """One profile reader for the controller and the simulated drive: it uses drives' tables, the
    base and the analysis, never the control layer, the application or the simulator."""
    forbidden = (*BUS_LIBRARIES, "haptic_bus.control", "haptic_bus.app", "haptic_bus.bench", "haptic_bus.identify",
                 "sim_drive")
    assert _offenders("haptic_bus.profile", forbidden) == []


def test_control_never_imports_the_application():
    assert _offenders("haptic_bus.control", ("haptic_bus.app", "haptic_bus.bench", "sim_drive")) == []


def test_protocol_tables_touch_no_bus():
    for tables in ("drives.cia301", "drives.cia402", "drives.modbus.register_map", "drives.errors", "drives.base"):
        assert _offenders(tables, BUS_LIBRARIES) == []


def _cycles() -> list[list[str]]:
    """Import cycles between our modules (a package counts as importing its ``__init__`` only)."""
    edges = {m: {t for t in targets if t in GRAPH and t != m} for m, targets in GRAPH.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:  # Tarjan's strongly connected components
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in edges[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(edges):
        if node not in index:
            visit(node)
    return found


def test_no_import_cycles_between_modules():
    assert _cycles() == []


@pytest.mark.parametrize("call", [
    "hb.check_passivity(mass=0.5, friction=0.1, period=1e-3, stiffness=200.0, damping=100.0, delay=1).to_dict()",
    "hb.load_profile('cia402-handle').gate().judge(hb.load_profile('cia402-handle').compiled_scene()).accepted",
    "hb.WallController and hb.PassivityGate and hb.compile_scene([hb.Wall('w', 0.0, -1, 10.0, 1.0)]).breaks",
])
def test_the_public_api_loads_no_bus_library(call):
    code = (f"import sys, json; import haptic_bus as hb; value = {call}; "
            f"print(json.dumps(sorted(m for m in {BUS_LIBRARIES!r} if m in sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
