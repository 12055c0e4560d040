"""Issue 20, drives that are not ours: the master against the simulated CiA-402 core behind real
vendors' EDS files (tests/data/eds: Technosoft iPOS and IDM/ISCM, WITTENSTEIN simco; origin and
license in its README).

- The simulated drive serves a vendor's dictionary as it stands: what the EDS lacks is absent
  (SDO abort 0x06020000 / 0x06090011), its PDO limits and default mappings are the EDS's.
- Commissioning reads what the drive has before it writes: one warning per missing safety object
  (what is then not protected), ``strict`` refuses naming them before any write, no SDO write
  ever reaches an absent object (a sniffer on the bus sees every SDO request), at start or close.
- A mapping the drive refuses (0x06040042 past a HighLimit, a fixed mapping) falls back to one
  object per PDO or to the drive's default mapping, and says so naming the object written.
- Done when: ``haptic-bus run`` with the shipped defaults against the issue's drive (the iPOS
  EDS without 0x6007: no 0x1016, no 0x6007, 0x1400 without sub 5, 8-byte PDOs) completes with
  exactly one warning per missing object; ``strict = true`` refuses it (exit 1, never enabled).

The master and the simulated drive meet on python-can's ``virtual`` bus in this process, except
for ``python -m sim_drive --eds`` (a subprocess on udp_multicast).  The runs use virtual time.
"""

from __future__ import annotations

import configparser
import hashlib
import pathlib
import re
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

import can
import canopen
import pytest

from drives.base import DriveScaling
from drives.canopen.drive import DEFAULT_TPDO, DEFAULT_TPDO_WITH_POSITION, CanopenDrive
from drives.canopen.link import NOTIFIER_CYCLE
from drives.cia402 import State
from drives.errors import DriveProtocolError
from drives.safety import VIRTUAL_TIME_CANOPEN_PATIENCE, SafetySettings
from haptic_bus.app.cli import main as haptic_bus_main
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.canopen.vendor_od import has
from sim_drive.cli import main as sim_main
from sim_drive.parameters import DeviceParameters
from sim_drive.profile import read_simulated_device
from tests.conftest import HEARTBEAT_WAIT, SDO_WAIT, new_bus_spec, unique_name, wait_for_heartbeat
from tests.run_rig import profile_variant, read_run, run_cli

EDS = pathlib.Path(__file__).resolve().parent / "data" / "eds"
IPOS, ISD860, SIMCO = EDS / "technosoft_ipos.eds", EDS / "technosoft_isd860.eds", EDS / "wittenstein_simco.eds"
NODE = 5
SDO_REQUEST = 0x600 + NODE
PERIOD = 1e-3  # s
TRUTH = DeviceParameters()
SCALING = DriveScaling(TRUTH.velocity_per_count, TRUTH.position_per_count, TRUTH.rated_torque, TRUTH.force_per_torque,
                       TRUTH.max_torque_permille)  # what the iPOS has no objects for: the simulated drive's own
ABSENT_SAFETY = [(0x1016, 1), (0x6007, 0), (0x1400, 5)]  # the issue's drive lacks these
WARNING_HEADS = ["0x1016 absent: the drive will not stop on the controller's heartbeat loss",
                 "0x6007 absent: the drive's reaction to a lost connection cannot be set to fault",
                 "0x1400:05 absent: the drive will not stop when the controller's torque targets (RPDO1) stop arriving"]


# ----------------------------------------------------------------------------- rig
def eds_variant(source: pathlib.Path, folder: pathlib.Path, drop: tuple[str, ...] = (),
                edits: Mapping[tuple[str, str], str] | None = None) -> pathlib.Path:
    """A copy of ``source`` in ``folder`` without the sections ``drop`` and with ``edits``
    ({(section, key): value}), through the INI parser canopen's EDS import uses."""
    parser = configparser.RawConfigParser(inline_comment_prefixes=(";",))
    parser.optionxform = str  # type: ignore[assignment,method-assign]  # EDS keys keep their case
    parser.read_string(source.read_text())
    for section in drop:
        assert parser.remove_section(section), section
    for (section, key), value in (edits or {}).items():
        assert parser.has_section(section), section
        parser.set(section, key, value)
    path = folder / f"{source.stem}-variant.eds"
    with path.open("w") as file:
        parser.write(file)
    return path


def issue_drive(folder: pathlib.Path) -> pathlib.Path:
    """The Technosoft iPOS EDS without 0x6007: no 0x1016, no 0x6007, 0x1400 with sub 0-2, 8-byte PDOs."""
    return eds_variant(IPOS, folder, drop=("6007",))


def bus_requests(sniffer: can.BusABC) -> tuple[list[tuple[int, int]], list[bytes]]:
    """What the sniffer saw (drained, bounded): (index, subindex) of every SDO download request to
    node 5, and every NMT command."""
    writes, nmt = [], []
    for _ in range(1_000_000):
        message = sniffer.recv(0.0)
        if message is None:
            return writes, nmt
        data = message.data
        if message.arbitration_id == SDO_REQUEST and len(data) == 8 and data[0] >> 5 == 1:  # initiate download
            writes.append((data[1] | data[2] << 8, data[3]))
        elif message.arbitration_id == 0:
            nmt.append(bytes(data))
    raise AssertionError("the sniffer never ran dry")


def sdo_writes(sniffer: can.BusABC) -> list[tuple[int, int]]:
    """(index, subindex) of every SDO download request to node 5 the sniffer saw."""
    return bus_requests(sniffer)[0]


@contextmanager
def vendor_drive(eds: pathlib.Path, **drive_kwargs: object) -> Iterator[tuple[CanopenDrive, CanopenSimDrive, can.BusABC]]:
    """The simulated drive behind ``eds`` and a master (not connected) on a fresh virtual bus, with a
    sniffer that sees every frame from before the drive boots."""
    channel = unique_name("vendor")
    sniffer = can.Bus(interface="virtual", channel=channel)
    sim = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, eds=eds, timing="ideal").start()
    drive_kwargs.setdefault("scaling", SCALING)
    drive_kwargs.setdefault("sdo_timeout", SDO_WAIT)
    drive_kwargs.setdefault("safety", SafetySettings().for_virtual_time(PERIOD))
    drive = CanopenDrive(NODE, interface="virtual", channel=channel, **drive_kwargs)  # type: ignore[arg-type]
    try:
        yield drive, sim, sniffer
    finally:
        drive.close()
        sim.stop()
        sniffer.shutdown()


def states_of(sim: CanopenSimDrive) -> list[State]:
    states: list[State] = []
    sim.drive.state_listeners.append(lambda old, new, number: states.append(new))
    return states


def cycle(drive: CanopenDrive, sim: CanopenSimDrive, torque: int, cycles: int = 5) -> None:
    """A few cycles commanding ``torque`` (per mille); the drive applies the last at its next SYNC."""
    for _ in range(cycles):
        inputs = drive.read_inputs()
        assert inputs.statusword == sim.drive.statusword
        drive.write_outputs(torque)
    drive.read_inputs()


# ----------------------------------------------------------------------------- the files
def test_the_vendor_files_are_the_published_ones_and_lack_what_the_readme_says() -> None:
    readme = (EDS / "README.md").read_text()
    for digest, name in re.findall(r"^([0-9a-f]{64})  (\S+\.eds)$", readme, re.M):
        assert hashlib.sha256((EDS / name).read_bytes()).hexdigest() == digest, name
    assert sorted(p.name for p in EDS.glob("*.eds")) == sorted(re.findall(r"^[0-9a-f]{64}  (\S+\.eds)$", readme, re.M))
    ipos, isd860, simco = (canopen.import_od(str(path), NODE) for path in (IPOS, ISD860, SIMCO))
    assert [has(ipos, *key) for key in [*ABSENT_SAFETY, (0x6071, 0), (0x6076, 0)]] == [False, True, False, True, False]
    assert [has(isd860, *key) for key in [*ABSENT_SAFETY, (0x6071, 0), (0x1A00, 2)]] == [False] * 5
    assert [has(simco, *key) for key in [*ABSENT_SAFETY, (0x6071, 0), (0x6076, 0)]] == [True, True, False, True, True]


# ----------------------------------------------------------------------------- the simulated drive behind an EDS
def sdo_abort(node: canopen.RemoteNode, index: int, subindex: int, write: bytes | None = None) -> int | None:
    """The abort code of an SDO upload (or download of ``write``), None if the drive answered."""
    try:
        if write is None:
            node.sdo.upload(index, subindex)
        else:
            node.sdo.download(index, subindex, write)
    except canopen.SdoAbortedError as exc:
        return int(exc.code)
    return None


@contextmanager
def client(channel: str) -> Iterator[canopen.RemoteNode]:
    network = canopen.Network()
    network.NOTIFIER_CYCLE = NOTIFIER_CYCLE  # canopen's 1 s recv block made each disconnect wait up to 1 s
    network.connect(interface="virtual", channel=channel)
    try:
        yield network.add_node(NODE, canopen.ObjectDictionary())
    finally:
        network.disconnect()


def test_what_the_eds_lacks_is_absent_and_its_pdo_limits_hold(channel: str) -> None:
    with CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, eds=ISD860) as sim, client(channel) as node:
        assert sdo_abort(node, 0x1016, 0) == 0x06020000  # no heartbeat consumer
        assert sdo_abort(node, 0x6007, 0) == 0x06020000
        assert sdo_abort(node, 0x6071, 0) == 0x06020000  # this drive has no CST
        assert sdo_abort(node, 0x1400, 5) == 0x06090011  # no RPDO deadline
        assert node.sdo.upload(0x1400, 0) == b"\x02"
        assert int.from_bytes(node.sdo.upload(0x6041, 0), "little") == sim.drive.statusword  # the core, where it has it
        # TPDO1's mapping holds one entry: a second does not exist, two are too many
        assert sdo_abort(node, 0x1800, 1, (0x80000185).to_bytes(4, "little")) is None  # invalid first
        assert sdo_abort(node, 0x1A00, 0, b"\x00") is None
        assert sdo_abort(node, 0x1A00, 2, (0x606C0020).to_bytes(4, "little")) == 0x06090011
        assert sdo_abort(node, 0x1A00, 1, (0x606C0020).to_bytes(4, "little")) is None
        assert sdo_abort(node, 0x1A00, 0, b"\x02") == 0x06040042
        assert sdo_abort(node, 0x1A00, 0, b"\x01") is None


def test_the_vendors_default_mapping_runs_and_its_own_objects_hold_their_values(channel: str, master: can.BusABC,
                                                                                 frames) -> None:
    with CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, eds=IPOS) as sim, client(channel) as node:
        manufacturer = min(i for i in sim.object_dictionary.indices if 0x2000 <= i < 0x6000)  # the vendor's, not ours
        variable = sim.object_dictionary[manufacturer]
        variable = variable if isinstance(variable, canopen.objectdictionary.ODVariable) else variable[1]
        assert node.sdo.upload(variable.index, variable.subindex) == variable.encode_raw(variable.default)
        frames.nmt_start(master)
        # iPOS default RPDO3 (COB-ID 0x405): controlword + target position 0x607A, which the core does not
        # implement: the drive keeps the value
        frames.send(master, 0x405, (0).to_bytes(2, "little") + (123456).to_bytes(4, "little", signed=True))
        frames.send(master, 0x80)
        tpdo1 = frames.recv_id(master, 0x185)  # default TPDO1: the statusword alone
        assert tpdo1 is not None and bytes(tpdo1.data) == sim.drive.statusword.to_bytes(2, "little")
        assert int.from_bytes(node.sdo.upload(0x607A, 0), "little", signed=True) == 123456


# ----------------------------------------------------------------------------- commissioning
def test_strict_refuses_the_issues_drive_before_writing_anything(tmp_path: pathlib.Path) -> None:
    with vendor_drive(issue_drive(tmp_path), safety=SafetySettings(strict=True).for_virtual_time(PERIOD)) as (
            drive, sim, sniffer):
        states = states_of(sim)
        with pytest.raises(DriveProtocolError) as refused:
            drive.connect()
        drive.close()
        assert sdo_writes(sniffer) == []  # refused from what it read: not one SDO write, at start or close
    message = str(refused.value)
    assert "refused under the strict safety policy ([safety] strict = true): the drive lacks 0x1016 (" in message
    assert message.index("0x1016 (") < message.index("0x6007 (") < message.index("0x1400:05 (")
    assert "\n" not in message and states == [] and sim.nmt_state == "PRE-OPERATIONAL"


@pytest.mark.parametrize("source, edits, tpdo_objects, expected", [
    pytest.param(  # the TPDO mappings enable 1 entry (HighLimit) though they declare 8: 0x06040042
        IPOS, {(f"1A0{n}sub0", "HighLimit"): "1" for n in range(4)}, DEFAULT_TPDO,
        {"refused": ("TPDO mapping packed: TPDO1 (0x6041, 0x606C) refused (SDO abort writing 0x1A00:00 "
                     "(TPDO1 mapping parameter.Number of mapped objects): 0x06040042"),
         "tpdo": [[0x6041], [0x606C]], "rpdo": [[0x6040, 0x6071]], "used": "one object per PDO: TPDO1 (0x6041), TPDO2 (0x606C)"},
        id="ipos-tpdo-highlimit-one-per-pdo"),
    pytest.param(  # the same for the RPDOs: controlword and torque travel in two frames
        IPOS, {(f"160{n}sub0", "HighLimit"): "1" for n in range(4)}, DEFAULT_TPDO,
        {"refused": "RPDO mapping packed: RPDO1 (0x6040, 0x6071) refused (SDO abort writing 0x1600:00",
         "tpdo": [[0x6041, 0x606C]], "rpdo": [[0x6040], [0x6071]], "used": "one object per PDO: RPDO1 (0x6040), RPDO2 (0x6071)"},
        id="ipos-rpdo-highlimit-split"),
    pytest.param(  # fixed TPDO mappings (sub 0 read-only): the drive's defaults, TPDO2 and TPDO3
        SIMCO, {(f"1A0{n}sub0", "AccessType"): "ro" for n in range(4)}, DEFAULT_TPDO_WITH_POSITION,
        {"refused": "refused (SDO abort writing 0x1A00:00 (TPDO1 mapping parameter.Number of mapped objects): 0x06010002",
         "tpdo": [[0x6041, 0x6064], [0x6041, 0x606C]], "rpdo": [[0x6040, 0x6071]],
         "used": "the drive's default mapping: TPDO2 (0x6041, 0x6064), TPDO3 (0x6041, 0x606C)"},
        id="simco-fixed-tpdo-default"),
    pytest.param(  # fixed RPDO mappings: simco's default RPDO4 carries exactly controlword + target torque
        SIMCO, {(f"160{n}sub0", "AccessType"): "ro" for n in range(4)}, DEFAULT_TPDO,
        {"refused": "refused (SDO abort writing 0x1600:00 (RPDO1 mapping parameter.Number of mapped objects): 0x06010002",
         "tpdo": [[0x6041, 0x606C]], "rpdo": [[0x6040, 0x6071]], "used": "the drive's default mapping: RPDO4 (0x6040, 0x6071)"},
        id="simco-fixed-rpdo-default"),
])
def test_a_refused_mapping_falls_back_says_so_and_the_cycle_runs(tmp_path: pathlib.Path, source: pathlib.Path,
                                                                  edits: dict, tpdo_objects: tuple, expected: dict) -> None:
    with vendor_drive(eds_variant(source, tmp_path, edits=edits), tpdo_objects=tpdo_objects) as (drive, sim, sniffer):
        drive.connect()
        found = drive.commissioned
        assert found is not None
        assert [[spec.index for spec in codec.entries] for codec in found.tpdo_codecs] == expected["tpdo"]
        assert [[spec.index for spec in codec.entries] for codec in found.rpdo_codecs] == expected["rpdo"]
        notes = found.mapping_notes
        assert any(expected["refused"] in note for note in notes), notes
        assert notes[-1].endswith(f"mapping in use: {expected['used']}"), notes
        drive.enable()
        cycle(drive, sim, 250)
        assert sim.drive.state is State.OPERATION_ENABLED and sim.drive.target_torque == 250
        inputs = drive.read_inputs()
        assert inputs.velocity == sim.drive.read_object(0x606C)
        if 0x6064 in [spec.index for codec in found.tpdo_codecs for spec in codec.entries]:
            assert inputs.position == sim.drive.read_object(0x6064)
        drive.disable()
        drive.close()
        heartbeat_consumer_writes = sdo_writes(sniffer).count((0x1016, 1))
    assert heartbeat_consumer_writes == (2 if source == SIMCO else 0)  # set and cleared at close; the iPOS has none


def test_an_object_no_pdo_can_carry_is_refused_naming_every_attempt(tmp_path: pathlib.Path) -> None:
    # the iPOS with 0x606C not PDO-mappable: every mapping is refused 0x06040041, and its default
    # TPDO4 (0x6041, 0x606C) cannot start either
    with vendor_drive(eds_variant(IPOS, tmp_path, edits={("606C", "PDOMapping"): "0"})) as (drive, sim, _sniffer):
        states = states_of(sim)
        with pytest.raises(DriveProtocolError) as refused:
            drive.connect()
    message = str(refused.value)
    assert message.startswith("CANopen node 5: no PDO mapping the drive accepts: packed: TPDO1 (0x6041, 0x606C), TPDO2 "
                              "(0x6064) refused (SDO abort writing 0x1A00:00 (TPDO1 mapping parameter.Number of mapped "
                              "objects): 0x06040041")
    assert message.count("0x06040041") == 2
    assert "one object per PDO: TPDO1 (0x6041), TPDO2 (0x606C), TPDO3 (0x6064) refused" in message
    assert message.endswith("the drive's default mapping: no set of the drive's PDOs carries 0x6041, 0x606C, 0x6064")
    assert "\n" not in message and states == []


def test_a_drive_without_target_torque_is_refused_in_one_line() -> None:
    with vendor_drive(ISD860) as (drive, sim, sniffer):
        states = states_of(sim)
        with pytest.raises(DriveProtocolError) as refused:
            drive.connect()
        assert sdo_writes(sniffer) == []
    assert str(refused.value) == ("CANopen node 5: the drive lacks 0x6071 Target torque: it cannot be driven in "
                                  "cyclic synchronous torque mode by this master")
    assert states == []


# ----------------------------------------------------------------------------- the real command lines
@contextmanager
def run_against(eds: pathlib.Path, profile: pathlib.Path | str) -> Iterator[tuple[list[str], CanopenSimDrive, can.BusABC,
                                                                                  list[State]]]:
    """The simulated drive of ``profile`` behind ``eds`` on a fresh virtual bus, a sniffer from
    before its boot-up, the ``run`` options that reach it and the states it enters."""
    channel = unique_name("vendor-run")
    truth, operator = read_simulated_device(profile).one_axis()
    with can.Bus(interface="virtual", channel=channel) as sniffer:
        sim = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, eds=eds, parameters=truth.parameters,
                              operator=operator, timing=truth.timing)
        states = states_of(sim)
        with sim:
            yield ["--interface", "virtual", "--channel", channel, "--node-id", str(NODE)], sim, sniffer, states


def test_a_run_against_the_issues_drive_completes_with_one_warning_per_missing_object(
        tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    with run_against(issue_drive(tmp_path), "cia402-handle") as (args, sim, sniffer, states):
        result = run_cli(capsys, "run", "cia402-handle", *args, "--virtual-time", "--no-plots", "--duration", "0.2",
                         "--out", str(out))
        writes, nmt = bus_requests(sniffer)  # the whole run
    assert result.code == 0, result.err
    warnings = [line for line in result.err_lines if line.startswith("WARNING")]
    prefix = "WARNING drives.canopen.commissioning: CANopen node 5: "
    assert len(warnings) == 3 and all(w.startswith(prefix + head) for w, head in zip(warnings, WARNING_HEADS)), warnings
    assert read_run(out)["link"]["safety_warnings"] == [w.removeprefix(prefix) for w in warnings]
    assert State.OPERATION_ENABLED in states and sim.drive.sync_count >= 200
    assert nmt[0] == bytes([0x82, NODE]) and nmt[-1] == bytes([0x80, NODE])  # from the reset to the closing frames
    assert len(writes) > 20 and not [w for w in writes if w[0] in (0x1016, 0x6007) or w == (0x1400, 5)]


def test_strict_refuses_the_issues_drive_on_the_command_line(tmp_path: pathlib.Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    profile = profile_variant(tmp_path, "cia402-handle", "strict", extra="[safety]\nstrict = true\n")
    out = tmp_path / "run"
    with run_against(issue_drive(tmp_path), profile) as (args, sim, sniffer, states):
        result = run_cli(capsys, "run", str(profile), *args, "--virtual-time", "--no-plots", "--duration", "0.2",
                         "--out", str(out))
        writes = sdo_writes(sniffer)
    assert result.code == 1
    (line,) = result.err_lines
    assert line.startswith("haptic-bus run: drive error: CANopen node 5: refused under the strict safety policy")
    assert all(label in line for label in ("0x1016 (", "0x6007 (", "0x1400:05 ("))
    assert states == [] and writes == [] and sim.drive.sync_count == 0
    assert read_run(out)["exit_reason"] == "drive error"


def test_python_m_sim_drive_eds_serves_a_vendor_dictionary_to_another_process(sim_process) -> None:
    spec = new_bus_spec("udp_multicast")
    process = sim_process(*spec.sim_args(), "--node-id", str(NODE), "--timing", "ideal", "--eds", str(IPOS))
    wait_for_heartbeat(spec, NODE, HEARTBEAT_WAIT, process)
    log = process.wait_for_line("serving on", HEARTBEAT_WAIT)
    assert ("the EDS lacks 0x1016:01 heartbeat consumer (stop on the master's heartbeat loss); 0x1400:05 RPDO1 event "
            "timer (receive deadline); 0x6072 max torque; 0x6076 motor rated torque: absent here too") in log
    drive = CanopenDrive(NODE, **spec.drive_kwargs(), scaling=SCALING, sdo_timeout=SDO_WAIT,
                         safety=SafetySettings().for_virtual_time(PERIOD), **VIRTUAL_TIME_CANOPEN_PATIENCE)
    try:
        drive.connect()
        assert [w.split(":")[0] for w in drive.safety_warnings] == ["0x1016 absent", "0x1400"]
        drive.enable()
        for _ in range(20):
            drive.read_inputs()
            drive.write_outputs(0)
        drive.disable()
    finally:
        drive.close()
    code, log = process.stop()
    assert code == 0, log[-2000:]


@pytest.mark.parametrize("argv, line", [
    (["--interface", "virtual", "--channel", "x", "--node-id", "5", "--eds", "/nonexistent/drive.eds"],
     "eds = '/nonexistent/drive.eds'"),
    (["--interface", "virtual", "--channel", "x", "--node-id", "5", "--eds", str(IPOS), "--od", "standard"],
     "an EDS alone (not with --od standard or a dictionary)"),
    (["--modbus", "tcp://127.0.0.1:0", "--eds", str(IPOS)], "CANopen options cannot be combined with --modbus: --eds"),
])
def test_bad_eds_options_get_one_line_and_exit_2(argv: list[str], line: str, capsys: pytest.CaptureFixture[str]) -> None:
    for command in (lambda: sim_main(argv), lambda: haptic_bus_main(["sim", *argv])):
        capsys.readouterr()
        assert command() == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("haptic-bus sim: error: ") and line in err[0], err
