"""The dependency direction the manual's layout (docs/layout.md) draws, read off the import graph of the source.

``drives`` imports nothing of ours; ``sim_drive`` uses drives and haptic_bus' analysis (the plant),
profile (the one profile reader) and base, never the controller; inside haptic_bus every module sits in one layer of
:data:`LAYERS` and imports only layers below its own (siblings on one level import neither
way); haptic_bus reaches sim_drive only through ``haptic_bus.app.rig``.  Every import statement is
counted, including the ones inside functions and under ``TYPE_CHECKING`` (a lazy import is still a
dependency).  A failure names each offending import as ``module imports target``.
"""

from __future__ import annotations

import ast
import functools
import json
import pathlib
import subprocess
import sys
from typing import Any

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("haptic_bus", "drives", "sim_drive")
BUS_LIBRARIES = ("can", "canopen", "pymodbus")
BASE = ("haptic_bus.errors", "haptic_bus.validation", "haptic_bus.console", "haptic_bus.lazy", "haptic_bus._version")

# haptic_bus bottom to top, as docs/layout.md draws it; the packages of one level are siblings.
LAYERS: tuple[tuple[str, ...], ...] = (
    BASE,
    ("haptic_bus.analysis",),
    ("haptic_bus.profile",),
    ("haptic_bus.control", "haptic_bus.identify"),
    ("haptic_bus.node", "haptic_bus.validate"),
    ("haptic_bus.app",),
    ("haptic_bus.bench", "haptic_bus.testing"),
)
FACADE = ("haptic_bus", "haptic_bus.__main__")  # the public API and python -m haptic_bus, above every layer


def _module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


BODIES = ("body", "orelse", "finalbody", "handlers", "cases")  # where a statement holds statements (handlers, cases: theirs)


def _imports(path: pathlib.Path) -> set[str]:
    """Every module an import statement of ``path`` names, at any depth.  An import is a statement, so only
    statements are visited (each compound statement's bodies), not the expressions in them: the same set as
    ``ast.walk`` over every node finds, for 0.3 s less CPU over the three packages."""
    found: set[str] = set()
    statements = list(ast.parse(path.read_text(), str(path)).body)
    while statements:
        node = statements.pop()
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.module and node.level == 0:
                found.add(node.module)
                found.update(f"{node.module}.{alias.name}" for alias in node.names)
        else:
            for field in BODIES:
                statements.extend(getattr(node, field, ()))
    return found


@functools.cache
def _graph() -> dict[str, set[str]]:
    """Each module of :data:`PACKAGES` and what it imports: parsed at the first test that asks, not at
    collection (0.8 s of CPU, which every pytest-xdist worker would pay, collecting every file)."""
    graph = {}
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            graph[_module_name(path)] = _imports(path)
    return graph


def _within(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def _offenders(modules: str, forbidden: tuple[str, ...], allowed: tuple[str, ...] = ()) -> list[str]:
    return sorted(
        f"{module} imports {target}"
        for module, targets in _graph().items() if _within(module, modules)
        for target in targets
        if any(_within(target, f) for f in forbidden) and not any(_within(target, a) for a in allowed)
    )


def _layer_of(module: str) -> tuple[int, str] | None:
    """(level, package) of a haptic_bus module, the facade above every level; None if in no layer."""
    if module in FACADE:
        return len(LAYERS), FACADE[0]
    for level, packages in enumerate(LAYERS):
        for package in packages:
            if _within(module, package):
                return level, "base" if packages is BASE else package  # the base's modules are one package
    return None


def _report(offenders: list[str], rule: str) -> str:
    return f"{rule}; offending imports:\n  " + "\n  ".join(offenders)


def test_the_graph_covers_every_package():
    assert {m.split(".")[0] for m in _graph()} == set(PACKAGES)
    assert {"drives.canopen.drive", "haptic_bus.analysis.criterion"} <= set(_graph())


def test_every_haptic_bus_module_sits_in_a_layer_the_layout_page_draws():
    homeless = sorted(m for m in _graph() if _within(m, "haptic_bus") and _layer_of(m) is None)
    assert not homeless, f"modules in no layer of LAYERS (add them to docs/layout.md and here): {homeless}"
    layout = (REPO / "docs" / "layout.md").read_text()
    drawn = next(line for line in layout.splitlines() if line.strip().startswith("haptic_bus layers: "))
    levels = [tuple(sorted(p.strip() for p in level.split("|"))) for level in drawn.split(": ", 1)[1].split(" <- ")]
    tested = [("base",), *(tuple(sorted(p.removeprefix("haptic_bus.") for p in level)) for level in LAYERS[1:])]
    assert levels == tested, f"docs/layout.md draws {drawn.strip()!r}; LAYERS here are {tested}"
    for package in (p for level in LAYERS[1:] for p in level):
        assert f"\n  {package.split('.')[-1]}/ " in layout, f"{package} is missing from docs/layout.md"


def test_haptic_bus_imports_only_layers_below():
    offenders = []
    for module, targets in _graph().items():
        home = _layer_of(module) if _within(module, "haptic_bus") else None
        if home is None:
            continue
        for target in targets:
            there = _layer_of(target) if _within(target, "haptic_bus") else None
            if there is not None and there[1] != home[1] and there[0] >= home[0]:
                where = "a sibling on its level" if there[0] == home[0] else "a layer above it"
                offenders.append(f"{module} imports {target} ({where})")
    levels = " <- ".join(" | ".join(p.removeprefix("haptic_bus.") for p in level) for level in LAYERS[1:])
    assert not offenders, _report(sorted(offenders), f"haptic_bus' layers are base <- {levels}")


def test_drives_import_nothing_of_ours_above_them():
    offenders = _offenders("drives", ("haptic_bus", "sim_drive"))
    assert not offenders, _report(offenders, "drives is the bottom layer")


def test_sim_drive_uses_only_the_analysis_the_profile_and_the_base_of_haptic_bus():
    offenders = _offenders("sim_drive", ("haptic_bus",), ("haptic_bus.analysis", "haptic_bus.profile", *BASE))
    assert not offenders, _report(offenders, "sim_drive uses haptic_bus' analysis, profile and base, never the controller")


def test_haptic_bus_reaches_the_simulator_only_through_the_rig():
    offenders = [o for o in _offenders("haptic_bus", ("sim_drive",)) if not o.startswith("haptic_bus.app.rig ")]
    assert not offenders, _report(offenders, "haptic_bus.app.rig is the one place haptic_bus reaches sim_drive")


@pytest.mark.parametrize("modules", ["haptic_bus.analysis", "haptic_bus.identify", "haptic_bus.validate", *BASE])
def test_the_pure_layers_import_no_drive_and_no_bus_code(modules):
    # the base re-exports drives' plain modules: errors (the root and drives' errors), ranges (the shared range check)
    allowed = {"haptic_bus.errors": ("drives.errors",), "haptic_bus.validation": ("drives.ranges",)}.get(modules, ())
    offenders = _offenders(modules, (*BUS_LIBRARIES, "drives", "sim_drive"), allowed)
    assert not offenders, _report(offenders, f"{modules} imports no bus library and nothing of drives")


def test_the_control_layer_imports_no_bus_library():
    offenders = _offenders("haptic_bus.control", BUS_LIBRARIES)
    assert not offenders, _report(offenders, "bus-facing controller code belongs to haptic_bus.node or above")


def test_the_profile_schema_touches_no_bus_and_no_simulator():
    """One profile reader for the controller and the simulated drive: it uses drives' tables, the
    base and the analysis (its place in LAYERS keeps it below the controller), no bus library and
    nothing of the simulator."""
    offenders = _offenders("haptic_bus.profile", (*BUS_LIBRARIES, "sim_drive"))
    assert not offenders, _report(offenders, "haptic_bus.profile is read by the controller and the simulator alike")


def test_protocol_tables_touch_no_bus():
    for tables in ("drives.cia301", "drives.cia402", "drives.modbus.register_map", "drives.errors", "drives.base"):
        offenders = _offenders(tables, BUS_LIBRARIES)
        assert not offenders, _report(offenders, f"{tables} is a table")


PUBLIC_CALLS = (
    "hb.check_passivity(mass=0.5, friction=0.1, period=1e-3, stiffness=200.0, damping=100.0, delay=1).to_dict()",
    "hb.load_profile('cia402-handle').gate().judge(hb.load_profile('cia402-handle').compiled_scene()).accepted",
    "hb.WallController and hb.PassivityGate and hb.compile_scene([hb.Wall('w', 0.0, -1, 10.0, 1.0)]).breaks",
)


@pytest.fixture(scope="module")
def loaded_in_turn() -> list[str]:
    """One fresh interpreter: first the analysis imported and what it loaded of drives, sim_drive, python-can
    and canopen printed; then each public-API call in turn, the bus libraries loaded so far printed after
    each.  A module stays loaded, so nothing listed after a step means that step alone loaded none of it
    either (one interpreter's start and numpy import, not four)."""
    code = "\n".join([
        "import sys, json; import haptic_bus.analysis.check, haptic_bus.analysis.coupled, haptic_bus.validation",
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('drives', 'sim_drive', 'can', 'canopen')))",
        "import haptic_bus as hb",
        *(f"value = {call}; print(json.dumps(sorted(m for m in {BUS_LIBRARIES!r} if m in sys.modules)))"
          for call in PUBLIC_CALLS)])
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1 - len(PUBLIC_CALLS):]


def test_importing_the_analysis_loads_nothing_of_drives(loaded_in_turn: list[str]) -> None:
    assert loaded_in_turn[0] == "['drives', 'drives.errors', 'drives.ranges']"  # what the base re-exports, nothing else


def _cycles() -> list[list[str]]:
    """Import cycles between our modules (a package counts as importing its ``__init__`` only)."""
    graph = _graph()
    edges = {m: {t for t in targets if t in graph and t != m} for m, targets in graph.items()}
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


def test_the_public_api_loads_no_bus_library(loaded_in_turn: list[str]) -> None:
    assert [json.loads(line) for line in loaded_in_turn[1:]] == [[]] * len(PUBLIC_CALLS)


VERDICT_COMMANDS = (
    (["check", "--json", "--mass", "1", "--friction", "20", "--period", "0.001", "--stiffness", "1000", "--damping", "5"],
     ("scipy.optimize", "matplotlib", "canopen", "pymodbus")),  # haptic-bus bench --only startup's FORBIDDEN
    (["profiles", "check", "gantry-3d", "--json"], ("matplotlib", "can", "canopen", "pymodbus")),  # the coupled gate may optimise
)


@pytest.fixture(scope="module")
def verdicts_in_turn() -> list[list[Any]]:
    """One fresh interpreter runs each of :data:`VERDICT_COMMANDS` in turn, printing its exit status and which of
    its forbidden modules are loaded so far.  A module stays loaded, so none listed after a command means that
    command alone loaded none of them either (one interpreter's start and numpy import, not two)."""
    code = "\n".join([
        "import sys, json, contextlib, io; from haptic_bus.app.cli import main",
        *(f"with contextlib.redirect_stdout(io.StringIO()): status = main({argv!r})\n"
          f"print(json.dumps([status, sorted(m for m in {forbidden!r} if m in sys.modules)]))"
          for argv, forbidden in VERDICT_COMMANDS)])
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return [json.loads(line) for line in out.stdout.strip().splitlines()[-len(VERDICT_COMMANDS):]]


@pytest.mark.parametrize("step", range(len(VERDICT_COMMANDS)), ids=[" ".join(argv[:2]) for argv, _ in VERDICT_COMMANDS])
def test_a_command_that_prints_a_verdict_imports_no_bus_library_nor_plots(verdicts_in_turn: list[list[Any]],
                                                                           step: int) -> None:
    """A verdict's command loads no bus library and no plotting (a JSON helper imported from the run
    folder once pulled canopen into every command's parser)."""
    assert verdicts_in_turn[step] == [0, []], VERDICT_COMMANDS[step]


PARSER_ONLY = ((["run", "--help"], 0), (["run", "cia402-handle", "--node-id", "500"], 2))  # argv, exit status


@pytest.fixture(scope="module")
def parser_only_in_turn() -> list[list[Any]]:
    """One fresh interpreter runs each of :data:`PARSER_ONLY` in turn, printing its exit status and which of
    numpy, the gates, the profiles and the bus libraries are loaded so far (a module stays loaded: none listed
    after the second means neither loaded any)."""
    forbidden = ("numpy", "haptic_bus.control", "haptic_bus.app.profiles", *BUS_LIBRARIES)
    code = "\n".join([
        "import sys, json, contextlib, io; from haptic_bus.app.cli import main",
        *(f"with contextlib.redirect_stdout(io.StringIO()): status = main({argv!r})\n"
          f"print(json.dumps([status, sorted(m for m in {forbidden!r} if m in sys.modules)]))" for argv, _ in PARSER_ONLY)])
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    lines = out.stdout.strip().splitlines()[-len(PARSER_ONLY):]
    assert len(lines) == len(PARSER_ONLY), out.stderr
    return [json.loads(line) for line in lines]


@pytest.mark.parametrize("step", range(len(PARSER_ONLY)), ids=["help", "refusal"])
def test_the_command_line_s_parser_imports_no_numpy(parser_only_in_turn: list[list[Any]], step: int) -> None:
    """Every ``haptic-bus`` process builds the whole parser: its help and a refusal at the arguments (exit
    2) import no numpy, no gate and no bus library (``profiles``' parser once imported the analysis:
    0.4 s of CPU for every command)."""
    assert parser_only_in_turn[step] == [PARSER_ONLY[step][1], []], PARSER_ONLY[step][0]


@pytest.mark.parametrize(("child", "forbidden"), [
    # the run's writer: rings, files, python-can's ASC writer only once a bus log is opened; numpy and rich only for a live view
    ("import haptic_bus.app.writer_process",
     ("numpy", "scipy", "mpmath", "matplotlib", "rich", "can", "canopen", "pymodbus", "haptic_bus.app.profiles",
      "haptic_bus.analysis", "haptic_bus.app.run_folder")),
    # the upload judge: the gates and the analysis they import, no bus, no plots, no live view
    ("import haptic_bus.node.verdicts as verdicts; verdicts._ready()",
     ("matplotlib", "rich", "can", "canopen", "pymodbus", "haptic_bus.app")),
    # haptic-bus sim on CANopen: the slave, not the master's drive; Modbus, scipy and plots only when asked
    ("import sim_drive.cli, sim_drive.canopen.slave",
     ("drives.canopen.drive", "drives.modbus.drive", "pymodbus", "scipy", "matplotlib", "rich", "haptic_bus.control",
      "haptic_bus.app")),
])
def test_a_child_process_imports_only_what_its_job_needs(child: str, forbidden: tuple[str, ...]) -> None:
    """Every real-time run spawns a writer and a judge process, and the suite starts the simulated
    drive dozens of times, each paying its imports at its start: what they import is pinned (the
    writer once imported the profiles, the gates, numpy and canopen through the run folder's module
    and a type, 0.4 s of CPU a run; the simulated drive the master's drive through its package)."""
    code = (f"import sys, json, multiprocessing.spawn; {child}; "
            f"print(json.dumps(sorted(m for m in sys.modules if any(m == f or m.startswith(f + '.') for f in {forbidden!r}))))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


# ----------------------------------------------------------------------------- one thread owns the bus

class BusCalls:
    """Which threads call the drive link's bus handle's ``send`` and ``recv`` while a controller cycles
    (between entering and leaving :meth:`CycleLoop._cyclic`), recorded by wrapping both on every bus
    the link opens; ``cycles_entered`` counts the cyclic phases."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        import contextlib
        import threading

        import drives.canopen.link as link_module
        from haptic_bus.control.cycle_loop import CycleLoop

        self.threads: dict[str, set[int]] = {"send": set(), "recv": set()}
        self.count = {"send": 0, "recv": 0}
        self.cycling = False
        self.cycles_entered = 0
        self.started = threading.Event()  # the first cyclic phase has begun
        self.names: list[str] = []  # the threads of this process as the last cyclic phase ended
        opened, cyclic = link_module.open_bus, CycleLoop._cyclic

        def open_recorded(*args, **kwargs):
            bus = opened(*args, **kwargs)
            for name in ("send", "recv"):
                setattr(bus, name, self._recorded(name, getattr(bus, name)))
            return bus

        @contextlib.contextmanager
        def recorded_phase(loop):
            with cyclic(loop):
                self.cycling, self.cycles_entered = True, self.cycles_entered + 1
                self.started.set()
                try:
                    yield
                finally:
                    self.cycling = False
                    self.names = sorted(thread.name for thread in threading.enumerate())

        monkeypatch.setattr(link_module, "open_bus", open_recorded)
        monkeypatch.setattr(CycleLoop, "_cyclic", recorded_phase)

    def _recorded(self, name, call):
        import threading

        def recorded(*args, **kwargs):
            if self.cycling:
                self.threads[name].add(threading.get_ident())
                self.count[name] += 1
            return call(*args, **kwargs)
        return recorded


def test_one_thread_owns_the_bus_of_a_one_axis_run_and_answers_its_uploads(monkeypatch, haptic_sim, tmp_path) -> None:
    """A virtual-time run of cia402-handle on the lock-step bus, with a gated upload from another
    handle while it cycles: the control thread (this test's) is the only one that sends or receives
    on the run's handle in the cyclic phase, the upload's SDO answers included; the gate never judges
    in this process while it cycles; the accepted wall is adopted at a cycle boundary."""
    import threading

    import haptic_bus as hb
    from haptic_bus.control.gate import PassivityGate
    from haptic_bus.node.upload import upload_walls

    calls = BusCalls(monkeypatch)
    judged_here: list[int] = []  # the gate judging in this process while it cycles: never (a worker process does)
    judge = PassivityGate.judge
    monkeypatch.setattr(PassivityGate, "judge",
                        lambda gate, scene: judged_here.append(calls.cycling) or judge(gate, scene))
    drive = haptic_sim("cia402-handle", interface="lockstep", node_id=5)
    profile = hb.load_profile("cia402-handle")
    wall = profile.compiled_scene().objects[0]
    options = hb.RunOptions(duration=60.0, pacing="virtual", out_dir=tmp_path / "run", live=False, plots=False,
                            bus_log=False)
    verdicts: list[str] = []

    def upload() -> None:  # another bus handle, another thread: a client as `haptic-bus upload` is
        try:
            if calls.started.wait(30.0):
                verdicts.append(upload_walls(drive.bus, 127, {0: (0.9 * wall.stiffness, wall.damping)}, timeout=5.0))
        finally:
            options.stop.event.set()  # the run ends once the upload is answered (or could not be)

    client = threading.Thread(target=upload, name="test-upload")
    client.start()
    result = hb.run_canopen(profile, drive.bus, node_id=5, options=options)
    client.join(timeout=30.0)
    assert result.exit_reason == "stopped", result.error
    assert verdicts and verdicts[0].startswith("accepted"), verdicts
    assert result.controller is not None and result.controller.applied_scenes == 1
    assert result.controller.scene.by_name()[wall.name].stiffness == 0.9 * wall.stiffness
    assert calls.cycles_entered == 1 and result.summary is not None and result.summary.cycles > 0
    assert judged_here and True not in judged_here  # judged here before cycling (the patch holds), never while cycling
    # while it cycles, neither the heartbeat thread nor the link's notifier runs; the judge's threads are named
    assert "heartbeat-127" not in calls.names and "canopen-notify" not in calls.names, calls.names
    assert {"verdict-collect", "verdict-feed"} <= set(calls.names), calls.names
    assert calls.threads == {"send": {threading.get_ident()}, "recv": {threading.get_ident()}}
    assert calls.count["send"] >= 2 * result.summary.cycles  # SYNC and RPDO every cycle, from this thread


def test_one_thread_owns_the_bus_of_a_three_axis_run_and_its_uploads_pass_the_coupled_gate(monkeypatch, tmp_path) -> None:
    """gantry-3d in virtual time against the three-axis simulator on the lock-step bus, two uploads
    from another bus handle while it cycles: in the cyclic phase only the control thread sends or
    receives on the run's one bus handle; the coupled gate (in the judge process) refuses a block of
    10^6 N/m and accepts a softer one, adopted at a cycle boundary."""
    import threading

    from haptic_bus.app.profiles import load_profile
    from haptic_bus.app.rig import simulated_axes_device
    from haptic_bus.app.runner import RunOptions, run
    from haptic_bus.errors import Refusal
    from haptic_bus.node.upload import upload_walls

    calls = BusCalls(monkeypatch)
    profile = load_profile("gantry-3d")
    bus = {"interface": "lockstep", "channel": f"one-thread-{tmp_path.name}"}
    block = [obj.name for obj in profile.compiled_scene().objects].index("block")
    options = RunOptions(60.0, pacing="virtual", out_dir=tmp_path / "run", live=False, plots=False)
    verdicts: list[str] = []

    def upload() -> None:  # another bus handle, another thread: a client as `haptic-bus upload` is
        try:
            if calls.started.wait(30.0):
                try:
                    upload_walls(bus, 127, {block: (1.0e6, 5.0)}, timeout=30.0)  # the judge shares 2 cores with the suite
                except Refusal as refused:
                    verdicts.append(str(refused))
                verdicts.append(upload_walls(bus, 127, {block: (1200.0, 5.0)}, timeout=30.0))
        finally:
            options.stop.event.set()  # the run ends once both are answered (or could not be)

    sim = simulated_axes_device(profile, bus).start()
    client = threading.Thread(target=upload, name="test-upload")
    client.start()
    try:
        result = run(profile, bus, options)
    finally:
        client.join(timeout=30.0)
        sim.stop()
    assert result.exit_reason == "stopped", result.error
    assert len(verdicts) == 2 and "passivity gate refused" in verdicts[0] and verdicts[1].startswith("accepted"), verdicts
    assert result.controller is not None and result.controller.applied_scenes == 1
    assert result.controller.scene.by_name()["block"].stiffness == 1200.0
    assert calls.cycles_entered == 1
    assert calls.threads == {"send": {threading.get_ident()}, "recv": {threading.get_ident()}}
    assert "heartbeat-127" not in calls.names and "canopen-notify" not in calls.names, calls.names
    assert result.summary is not None  # one SYNC and three RPDOs every cycle (and a heartbeat every round(heartbeat / T))
    assert calls.count["send"] >= 4 * result.summary.cycles


def test_the_bus_log_tap_takes_the_cycles_tpdos_as_their_parts_on_udp_multicast(canopen_rig) -> None:
    """The bus log's tap (a PartsTap) gets the cycle's TPDOs from the control thread's receive as their parts, and
    the ring holds them as received frames, between the SYNC and the RPDO they answer."""
    from drives.canopen.link import PartsTap
    from haptic_bus.app.bus_log import FRAME, FrameTap, frames
    from haptic_bus.control.ring import Ring

    ring = Ring(FRAME, 256)
    tap = FrameTap(ring)
    handed: list[int] = []
    received = tap.received

    def counted(stamp: float, can_id: int, data: bytes, /) -> None:
        handed.append(can_id)
        received(stamp, can_id, data)

    tap.received = counted  # type: ignore[method-assign]  # the same tap, its parts counted
    assert isinstance(tap, PartsTap)
    with canopen_rig(interface="udp_multicast") as rig:
        drive = rig.drive
        node = drive.node_id
        drive.link.tap = tap
        with drive.cyclic() as cycle:
            for _ in range(3):
                cycle.read()
                cycle.write(0)
        drive.link.tap = None
    logged = [(m.arbitration_id, not m.is_rx) for m in frames(ring.read_from(0)[1])]
    cyclic = [frame for frame in logged if frame[0] in (0x80, 0x180 + node, 0x280 + node, 0x200 + node)]
    assert cyclic == [(0x80, True), (0x180 + node, False), (0x280 + node, False), (0x200 + node, True)] * 3
    assert handed == [0x180 + node, 0x280 + node] * 3  # every TPDO of the cycle came as its parts


@pytest.mark.parametrize("interface", ["lockstep", "udp_multicast"])
def test_the_link_tap_sees_every_frame_sent_and_received(canopen_rig, interface: str) -> None:
    """The tap (drives.canopen.link) sees canopen's SDO request and its answer outside the cyclic
    phase, and the cycle's SYNC, TPDOs and RPDO in it, each marked sent or received.  On udp_multicast
    the cycle reads its TPDOs as their parts (``recv_parts``): a tap that takes no parts, as this one,
    gets each as a message built of them."""
    import can

    from drives.cia402 import STATUSWORD

    with canopen_rig(interface=interface) as rig:
        drive = rig.drive
        node = drive.node_id
        seen: list[tuple[int, bool]] = []
        stamps: dict[tuple[int, bool], float] = {}

        def tap(msg: can.Message, sent: bool) -> None:
            seen.append((msg.arbitration_id, sent))
            stamps[msg.arbitration_id, sent] = msg.timestamp

        drive.link.tap = tap
        drive.read_object(STATUSWORD)  # SDO, answered through canopen's notifier
        # the notifier may tap the answer before the sender taps its request; the stamps keep the order
        sdo = sorted((frame for frame in seen if frame[0] in (0x600 + node, 0x580 + node)), key=stamps.__getitem__)
        assert sdo == [(0x600 + node, True), (0x580 + node, False)]
        seen.clear()
        with drive.cyclic() as cycle:
            for _ in range(3):
                cycle.read()
                cycle.write(0)
        drive.link.tap = None
    cyclic = [frame for frame in seen if frame[0] in (0x80, 0x180 + node, 0x280 + node, 0x200 + node)]
    assert cyclic == [(0x80, True), (0x180 + node, False), (0x280 + node, False), (0x200 + node, True)] * 3
