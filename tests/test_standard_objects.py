"""The master meets a drive with the standard CiA-301/402 dictionary only (no EDS): scaling from
0x6076, 0x6072 and the factor group (0x608F, 0x6090, 0x6091, 0x6092, 0x60A8, 0x60A9), the
profile where the drive has no object for a factor, a manufacturer object only where an EDS
names it, and a conflict between the drive and the profile refused before the drive is enabled.

The drive is the simulated one with ``od="standard"`` (``haptic-bus sim --od standard``), a real
CANopen slave on python-can's virtual bus, and once in a second process on udp_multicast.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any

import canopen
import numpy as np
import pytest

from drives.canopen.drive import CanopenDrive
from drives.cia402_master import merge_scaling
from drives.errors import DriveError, DriveProtocolError
from drives.factor_group import FactorGroup, SiUnit, derive
from drives.safety import SafetySettings
from haptic_bus.control.record import COLUMNS
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.canopen.standard_od import encode, standard_dictionary
from sim_drive.eds import eds_path
from sim_drive.parameters import DeviceParameters
from tests.conftest import HEARTBEAT_WAIT, SDO_WAIT, new_bus_spec

if TYPE_CHECKING:
    from canopen.objectdictionary import ObjectDictionary

    from haptic_bus.app.profiles import Profile
    from haptic_bus.app.runner import RunResult

NODE = 5
PROFILE_SOURCE = "profile [device]"
# The sim's default factor: 2 pi / 50 m per motor revolution is irrational; its feed constant is
# the closest 32-bit fraction, 1697716670 / 1351 in 0.1 um, 4.5e-14 off (module docstring of
# sim_drive.canopen.standard_od).  Every other factor is a power of ten or an integer: exact.
FEED_ROUNDING = 1e-12
STANDARD_SOURCES = {  # where the master finds each scaling field on a drive with the standard objects only
    "velocity_per_count": "0x60A9", "position_per_count": "0x60A8", "rated_torque": "0x6076",
    "force_per_torque": "0x6091/0x6092/0x60A8", "max_torque_permille": "0x6072",
}


def open_drive(channel: str, **kwargs: Any) -> CanopenDrive:
    """The master, no EDS, on the virtual ``channel``; SafetySettings for a test that paces nothing."""
    kwargs.setdefault("safety", SafetySettings().for_virtual_time(1e-3))
    kwargs.setdefault("sdo_timeout", SDO_WAIT)
    return CanopenDrive(NODE, interface="virtual", channel=channel, **kwargs)


@contextmanager
def master_of(sim: CanopenSimDrive, channel: str, **kwargs: Any) -> Iterator[CanopenDrive]:
    """The master (:func:`open_drive`) of the simulated drive ``sim``; on exit the master is closed and ``sim`` stopped."""
    drive = open_drive(channel, **kwargs)
    try:
        yield drive
    finally:
        drive.close()
        sim.stop()


def set_default(dictionary: ObjectDictionary, index: int, subindex: int, value: int) -> None:
    """Make the slave serve ``value`` at ``index:subindex`` (a dictionary used without the standard objects' callback)."""
    variable = dictionary.get_variable(index, subindex)
    assert variable is not None
    variable.default = value


def standard_sim(channel: str, **parameters: Any) -> CanopenSimDrive:
    return CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, timing="ideal",
                           parameters=DeviceParameters(**parameters), od="standard").start()


# ----------------------------------------------------------------------------- the encoding, no bus

def test_unit_encoding_follows_the_published_examples() -> None:
    """FD010000h mm and FF410000h a tenth of a degree (Nanotec), 00B44700h rpm and FDB44700h
    0.001 rpm (Synapticon), FD010300h mm/s (heig-vd canopen-stack): byte 3 a signed exponent,
    byte 2 the unit, byte 1 the time unit."""
    assert SiUnit.decode(0xFD010000) == SiUnit(-3, 0x01, 0) and SiUnit(-3, 0x01).encode() == 0xFD010000
    assert SiUnit.decode(0xFF410000) == SiUnit(-1, 0x41, 0)
    assert SiUnit.decode(0x00B44700) == SiUnit(0, 0xB4, 0x47) and SiUnit.decode(0xFDB44700).exponent == -3
    assert SiUnit.decode(0xFD010300) == SiUnit(-3, 0x01, 0x03)
    assert str(SiUnit.decode(0xFD010300)) == "10^-3 m/s"


def test_a_lead_screw_axis_is_derived_from_its_objects() -> None:
    """A 5 mm lead screw behind a 10:1 gear, a 4096-increment encoder, positions in um, velocity
    in rpm of the screw: 0x6064 counts 1 um; the screw moves 0.5 mm per motor revolution, so a
    lossless transmission gives 2 pi / 0.0005 m N per N m; 1 rpm of the screw is 5 mm / 60 s."""
    group = FactorGroup(position_unit=0xFA010000, velocity_unit=0x00B44700, position_encoder=(4096, 1),
                        gear_ratio=(10, 1), feed_constant=(5000, 1))
    found, notes = derive("n", group)
    assert found["position_per_count"].value == 1e-6 and found["position_per_count"].source == "0x60A8"
    assert found["force_per_torque"].value == pytest.approx(math.tau / 0.0005, rel=1e-15)
    assert found["force_per_torque"].source == "0x6091/0x6092/0x60A8"
    assert found["force_per_torque"].tolerance == 0.5 / 5000  # the feed is whole um
    assert found["velocity_per_count"].value == pytest.approx(0.005 / 60, rel=1e-15)
    assert found["velocity_per_count"].source == "0x60A9/0x6092/0x60A8"
    assert notes == ()
    # velocity in encoder increments per second: 0.5 mm per motor revolution over 4096 increments
    found, _ = derive("n", FactorGroup(position_unit=0xFA010000, velocity_unit=0x00B50300, position_encoder=(4096, 1),
                                       gear_ratio=(10, 1), feed_constant=(5000, 1)))
    assert found["velocity_per_count"].value == pytest.approx(0.0005 / 4096, rel=1e-15)
    assert found["velocity_per_count"].source == "0x60A9/0x608F/0x6091/0x6092/0x60A8"


def test_increments_as_the_position_unit_state_no_length() -> None:
    """0x60A8 = increments (a drive's default): no object says how long an increment is."""
    found, notes = derive("n", FactorGroup(position_unit=0x00B50000, velocity_unit=0x00B50300,
                                           position_encoder=(1 << 20, 1), gear_ratio=(1, 1), feed_constant=(1 << 20, 1)))
    assert found == {}
    assert any("not a length" in note for note in notes) and any(note.startswith("velocity_per_count") for note in notes)


def test_the_simulated_drive_states_its_default_scaling_in_standard_objects() -> None:
    values = encode(DeviceParameters())
    assert values[0x60A8, 0] == 0xF9010000 and values[0x60A9, 0] == 0xFA010300  # 10^-7 m, 10^-6 m/s
    assert (values[0x6092, 1], values[0x6092, 2]) == (1697716670, 1351) and (values[0x6091, 1], values[0x6091, 2]) == (1, 1)
    feed = Fraction(values[0x6092, 1], values[0x6092, 2]) * Fraction(1, 10**7)
    assert abs(feed / (Fraction(math.tau) / 50) - 1) < 5e-14  # the documented rounding


# ----------------------------------------------------------------------------- on the bus

def test_the_master_derives_every_factor_from_the_standard_objects(channel: str) -> None:
    sim = standard_sim(channel)
    with master_of(sim, channel) as drive:
        drive.connect()
        truth = sim.drive.parameters
        scaling = drive.scaling
        # powers of ten and integers: exact; the feed constant's fraction: FEED_ROUNDING
        assert scaling.velocity_per_count == truth.velocity_per_count
        assert scaling.position_per_count == truth.position_per_count
        assert scaling.rated_torque == truth.rated_torque and scaling.max_torque_permille == truth.max_torque_permille
        assert scaling.force_per_torque == pytest.approx(truth.force_per_torque, rel=FEED_ROUNDING)
        assert drive.scaling_sources == {
            "velocity_per_count": "0x60A9", "position_per_count": "0x60A8", "rated_torque": "0x6076",
            "force_per_torque": "0x6091/0x6092/0x60A8", "max_torque_permille": "0x6072",
        }
        report = drive.scaling_report
        assert report is not None and report.notes == ()
        lines = report.lines()
        assert lines[1] == "position_per_count = 1e-07 m from 0x60A8 (10^-7 m per count)"
        assert report.to_dict()["factors"]["force_per_torque"]["tolerance"] == pytest.approx(0.5 / 1697716670)
        drive.enable()
        for _ in range(5):
            drive.read_inputs()
            drive.write_outputs(100)
        drive.disable()


def test_velocity_in_increments_comes_through_the_velocity_encoder(channel: str) -> None:
    """2.5 um/s per count is no power of ten: the drive reports increments per second and the
    increments per motor revolution in 0x6090 (67664 revolutions for 3401163605 increments)."""
    sim = standard_sim(channel, velocity_per_count=2.5e-6)
    with master_of(sim, channel) as drive:
        drive.connect()
        assert drive.scaling.velocity_per_count == pytest.approx(2.5e-6, rel=FEED_ROUNDING)
        assert drive.scaling_sources["velocity_per_count"] == "0x60A9/0x6090/0x6091/0x6092/0x60A8"
        assert struct.unpack("<I", drive.sdo_read(0x60A9, 0))[0] == 0x00B50300


def test_a_drive_lacking_the_factor_group_falls_back_to_the_profile(channel: str) -> None:
    """The haptic OD has no factor group and, without its EDS, the master reads no manufacturer
    object: 0x6076 and 0x6072 from the drive, the other three from the profile."""
    sim = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, timing="ideal").start()
    given = DeviceParameters().scaling
    with master_of(sim, channel, scaling=given, scaling_source=PROFILE_SOURCE) as drive:
        drive.connect()
        assert drive.scaling == given
        assert drive.scaling_sources == {
            "velocity_per_count": PROFILE_SOURCE, "position_per_count": PROFILE_SOURCE, "rated_torque": "0x6076",
            "force_per_torque": PROFILE_SOURCE, "max_torque_permille": "0x6072",
        }
        report = drive.scaling_report
        assert report is not None
        assert any("no 0x60A8" in note for note in report.notes)
        rated = next(f for f in report.factors if f.name == "rated_torque")
        assert [r.source for r in rated.agreed] == [PROFILE_SOURCE]  # the profile's value checked against 0x6076


def test_a_drive_reporting_increments_falls_back_to_the_profile(channel: str) -> None:
    """The cia402-handle's scaling (0x6064 in 2^20 increments per revolution of a 20 mm pulley)
    is no power of ten: 0x60A8 says increments, no length is stated, the profile gives it."""
    per_increment = 2 * math.pi * 0.02 / 2**20
    sim = standard_sim(channel, velocity_per_count=per_increment, position_per_count=per_increment)
    given = sim.drive.parameters.scaling
    with master_of(sim, channel, scaling=given, scaling_source=PROFILE_SOURCE) as drive:
        drive.connect()
        assert drive.scaling == given
        for name in ("velocity_per_count", "position_per_count", "force_per_torque"):
            assert drive.scaling_sources[name] == PROFILE_SOURCE
        assert struct.unpack("<I", drive.sdo_read(0x60A8, 0))[0] == 0x00B50000
        assert struct.unpack("<II", drive.sdo_read(0x608F, 1) + drive.sdo_read(0x608F, 2)) == (1 << 20, 1)


def test_a_feed_constant_that_disagrees_with_the_profile_is_refused_before_enabling(channel: str) -> None:
    """The drive's 0x6092 says 52 N/(N m) (a 19.2 mm pulley), the profile 50: both named, connect()
    fails, and the drive never leaves SWITCH ON DISABLED."""
    sim = standard_sim(channel, force_per_torque=52.0)
    transitions: list[object] = []
    sim.drive.state_listeners.append(lambda old, new, number: transitions.append((old, new)))
    with master_of(sim, channel, scaling=DeviceParameters().scaling, scaling_source=PROFILE_SOURCE) as drive:
        with pytest.raises(DriveError) as refused:
            drive.connect()
    # the drive's value, printed to 12 digits, is 52 (exact to far better than FEED_ROUNDING), the profile's 50
    assert ("scaling conflict for force_per_torque: 52 N/(N m) from 0x6091/0x6092/0x60A8 but 50 N/(N m) from "
            f"{PROFILE_SOURCE}") in str(refused.value)
    assert transitions == []


def test_a_feed_within_its_rounding_is_accepted(channel: str) -> None:
    """A feed of 1256637 x 0.1 um per revolution (2 pi x 20 mm, rounded to the unit): a profile
    with the exact 50 N/(N m) agrees within 0.5 / 1256637; the drive's value is used."""
    dictionary = standard_dictionary(NODE, DeviceParameters())
    for index in (0x6092, 0x608F):
        set_default(dictionary, index, 1, 1256637)
        set_default(dictionary, index, 2, 1)
    sim = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, timing="ideal", dictionary=dictionary).start()
    with master_of(sim, channel, scaling=DeviceParameters().scaling, scaling_source=PROFILE_SOURCE) as drive:
        drive.connect()
        assert drive.scaling.force_per_torque == pytest.approx(math.tau / 0.1256637, rel=1e-15)
        assert drive.scaling_sources["force_per_torque"] == "0x6091/0x6092/0x60A8"


@pytest.mark.parametrize(("index", "subindex", "value", "allowed"), [
    (0x608F, 1, 0, "1..4294967295"),
    (0x6092, 2, 0, "1..4294967295"),
    (0x6091, 2, 0, "1..4294967295"),
    (0x60A8, 0, 0xFD770000, "a unit (bits 16-23) among"),
    (0x60A8, 0, 0x7F010000, "an exponent (bits 24-31) in -18..18"),
    (0x60A9, 0, 0xFA014800, "a time unit (bits 8-15) among 03h s, 47h min"),
])
def test_malformed_standard_objects_are_typed_errors(channel: str, index: int, subindex: int, value: int,
                                                     allowed: str) -> None:
    dictionary = standard_dictionary(NODE, DeviceParameters())
    set_default(dictionary, index, subindex, value)
    sim = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, timing="ideal", dictionary=dictionary).start()
    with master_of(sim, channel) as drive:
        with pytest.raises(DriveProtocolError) as bad:
            drive.connect()
    message = str(bad.value)
    assert f"0x{index:04X}:{subindex:02X} (" in message and f") = {value} (0x{value:08X}) is invalid; allowed: " in message
    assert allowed in message.partition("allowed: ")[2]
    assert sim.drive.state.value == "SWITCH ON DISABLED"


def test_the_eds_path_still_reads_the_manufacturer_objects(channel: str) -> None:
    """With the EDS that names them, 0x2001:01-03 give the three factors; the profile agrees."""
    sim = CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE, timing="ideal").start()
    with master_of(sim, channel, eds=eds_path(), scaling=DeviceParameters().scaling, scaling_source=PROFILE_SOURCE) as drive:
        drive.connect()
        assert drive.scaling == sim.drive.parameters.scaling
        sources = drive.scaling_sources
        assert (sources["velocity_per_count"], sources["position_per_count"], sources["force_per_torque"]) == (
            "0x2001:01", "0x2001:02", "0x2001:03")
        report = drive.scaling_report
        assert report is not None
        assert all(PROFILE_SOURCE in [r.source for r in f.agreed] for f in report.factors)


def test_the_standard_dictionary_has_no_manufacturer_area(channel: str) -> None:
    """No object in 0x2000-0x5FFF (abort 0x06020000); the factor group is read-only (0x06010002)."""
    sim = standard_sim(channel)
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    node = network.add_node(NODE, canopen.ObjectDictionary())
    try:
        for index, subindex in ((0x2000, 1), (0x2001, 2), (0x2002, 1), (0x2010, 1)):
            with pytest.raises(canopen.SdoAbortedError) as aborted:
                node.sdo.upload(index, subindex)
            assert aborted.value.code == 0x06020000
        with pytest.raises(canopen.SdoAbortedError) as refused:
            node.sdo.download(0x6092, 1, struct.pack("<I", 7))
        assert refused.value.code == 0x06010002
        assert struct.unpack("<I", node.sdo.upload(0x6076, 0))[0] == 200
    finally:
        network.disconnect()
        sim.stop()


def test_reconfigured_parameters_show_in_the_objects(channel: str) -> None:
    """The objects follow the drive's parameters: a new pulley, a new feed."""
    sim = standard_sim(channel)
    with master_of(sim, channel) as drive:
        drive.connect()
        sim.drive.reconfigure(force_per_torque=100.0)
        feed = struct.unpack("<II", drive.sdo_read(0x6092, 1) + drive.sdo_read(0x6092, 2))
        assert float(Fraction(*feed) / 10**7) == pytest.approx(math.tau / 100.0, rel=FEED_ROUNDING)


# ----------------------------------------------------------------------------- closed loop

def _run(profile: Profile, od: str, tmp: Path, channel: str) -> RunResult:
    """``run_canopen`` (the runner of ``haptic-bus run``) against the simulated drive in this process."""
    from haptic_bus.app.rig import profile_operator
    from haptic_bus.app.runner import RunOptions, run_canopen

    sim = CanopenSimDrive({"interface": "lockstep", "channel": channel}, NODE, timing=profile.loop.timing,
                          parameters=DeviceParameters(**profile.sim_device_parameters()),  # type: ignore[arg-type]
                          operator=profile_operator(profile), od=od).start()
    try:
        result = run_canopen(profile, {"interface": "lockstep", "channel": channel}, NODE,
                             RunOptions(1.0, pacing="virtual", out_dir=tmp, live=False, plots=False),
                             controller_node_id=42)
    finally:
        sim.stop()
    assert result.exit_reason == "completed", result.error
    return result


@pytest.mark.slow
def test_the_standard_path_closes_the_same_loop_as_the_haptic_one(channel: str, tmp_path: Path) -> None:
    """seed-ideal for 1 s of virtual time, the operator's 1 N step at 0.1 s: the same record,
    column for column (time, position, velocity, wall force, torque, energy, scene, scale, late).

    Exact equality is the expectation: the plant is the same (the sim keeps the exact 50
    N/(N m)), the velocity factor is 1e-6 on both paths, so x, v, the wall force and the
    observer's energy are computed from the same numbers; the per-mille torque rounds
    ``force / (rated x force_per_torque / 1000)``, whose factor differs by 4.5e-14 on the
    standard path, which moves a rounding only within ~1e-10 of a half per mille -- it did not
    in this deterministic run, and the comparison would show it if it ever did."""
    from haptic_bus.app.profiles import load_profile

    profile = load_profile("seed-ideal")
    haptic = _run(profile, "haptic", tmp_path / "haptic", f"{channel}-haptic")
    standard = _run(profile, "standard", tmp_path / "standard", f"{channel}-standard")
    assert haptic.controller is not None and standard.controller is not None
    a, b = haptic.controller.record.array(), standard.controller.record.array()
    assert a.shape == b.shape == (1000, len(COLUMNS))
    # all but when and how long the machine took, and whether a TPDO missed its 50 ms timeout (a loaded
    # machine can pause the simulated drive's thread that long even in virtual time: it is counted, not hidden)
    machine = ("wall_clock_s", "monotonic_s", "compute_s", "input_age", "late", "energy_j")
    loop = [COLUMNS.index(name) for name in COLUMNS if name not in machine]
    assert np.array_equal(a[:, loop], b[:, loop])
    assert np.count_nonzero(a[:, COLUMNS.index("input_age")]) + np.count_nonzero(b[:, COLUMNS.index("input_age")]) <= 5
    # the port's energy sums b dx^2/T - F dx with dx in counts times 0x6064's size, which the standard
    # path derives from the factor group to 4.5e-14 relative: the sums agree to round-off
    energy = COLUMNS.index("energy_j")
    assert np.allclose(a[:, energy], b[:, energy], rtol=1e-11, atol=1e-15)
    assert np.max(np.abs(a[:, COLUMNS.index("position_m")])) > 4e-3  # the step pushed the handle 5 mm into the wall
    document = json.loads((tmp_path / "standard" / "run.json").read_text())
    assert document["scaling"]["sources"] == STANDARD_SOURCES and document["summary"]["cycles"] == 1000
    assert json.loads((tmp_path / "haptic" / "run.json").read_text())["scaling"]["sources"]["position_per_count"] != "0x60A8"


def test_haptic_bus_sim_od_standard_serves_standard_objects_to_another_process(sim_process: Callable[..., Any]) -> None:
    """``haptic-bus sim --od standard`` as a process of its own: the master here finds the scaling in
    the standard objects (the closed loop on them runs in process, above)."""
    spec = new_bus_spec("udp_multicast")
    sim = sim_process(*spec.sim_args(), "--node-id", str(NODE), "--profile", "seed-ideal", "--od", "standard")
    sim.wait_for_line("standard objects only", HEARTBEAT_WAIT)
    drive = CanopenDrive(NODE, **spec.drive_kwargs(), safety=SafetySettings().for_virtual_time(1e-3))
    try:
        drive.connect()
        assert drive.scaling_sources == STANDARD_SOURCES
    finally:
        drive.close()
    code, log = sim.stop()
    assert code == 0, log[-2000:]


def test_sim_od_is_a_canopen_option() -> None:
    from sim_drive.cli import main

    assert main(["--modbus", "tcp://127.0.0.1:0", "--od", "standard"]) == 2
    assert main(["--interface", "virtual", "--channel", "x", "--node-id", "5", "--od", "nonsense"]) == 2



@pytest.mark.parametrize("value", [0.0, -0.32, math.inf, math.nan])
def test_a_scaling_factor_the_drive_reports_below_zero_or_not_finite_is_a_protocol_error(value: float) -> None:
    """The drive's reading is checked by the shared range check (drives.ranges.real_in_range), in its words."""
    with pytest.raises(DriveProtocolError) as refused:
        merge_scaling("CANopen node 5", None, {"rated_torque": (value, "0x6076")})
    assert str(refused.value) == (f"CANopen node 5: scaling rated_torque = {value!r} (from 0x6076); must be a finite "
                                  "real > 0")
