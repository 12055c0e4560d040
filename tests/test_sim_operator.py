"""Operator-force models: values, validation, recordings, and how profiles/0x2010 build them."""

from __future__ import annotations

import math
import pathlib

import pytest

from haptic_bus.errors import ParameterError
from sim_drive.operator import (
    OPERATOR_CODES,
    Chirp,
    ConstantPush,
    HandModel,
    NoOperator,
    RecordedForce,
    Sinusoid,
    StepPush,
    operator_code,
    operator_from_code,
    operator_from_table,
)


def test_simple_models() -> None:
    assert NoOperator().force(1.0, 2.0, 3.0) == 0.0
    assert ConstantPush(-2.5).force(0.0, 9.0, 9.0) == -2.5
    step = StepPush(3.0, start=0.01)
    assert (step.force(0.0099, 0, 0), step.force(0.01, 0, 0)) == (0.0, 3.0)
    sine = Sinusoid(2.0, 5.0, phase=math.pi / 2, offset=1.0)
    assert sine.force(0.0, 0, 0) == pytest.approx(3.0)
    assert sine.force(0.1, 0, 0) == pytest.approx(1.0 + 2.0 * math.cos(math.pi), abs=1e-12)


def test_chirp_sweeps_linearly_and_stops() -> None:
    chirp = Chirp(1.0, f0=0.0, f1=100.0, duration=1.0)
    # phase 2 pi (50 t^2): a quarter cycle at t = sqrt(1/200)
    assert chirp.force(math.sqrt(1 / 200), 0, 0) == pytest.approx(1.0, abs=1e-12)
    assert chirp.force(1.0001, 0, 0) == 0.0 and chirp.force(-1e-3, 0, 0) == 0.0


def test_hand_model_is_a_spring_damper_to_a_moving_setpoint() -> None:
    hand = HandModel(stiffness=200.0, damping=5.0, start=0.01, speed=0.1)
    # set-point 0.01 + 0.1 t; at t = 0.5: 0.06 m, 0.1 m/s
    assert hand.force(0.5, 0.05, 0.0) == pytest.approx(200.0 * 0.01 + 5.0 * 0.1)
    wobble = HandModel(100.0, 0.0, amplitude=0.02, frequency=1.0)
    assert wobble.force(0.25, 0.0, 0.0) == pytest.approx(2.0)


def test_recording_hold_and_linear(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "push.csv"
    path.write_text("time,force\n0.0,0.0\n0.1,1.0\n0.3,-1.0\n")
    hold = RecordedForce.from_csv(path)
    linear = RecordedForce.from_csv(path, "linear")
    assert [hold.force(t, 0, 0) for t in (-0.1, 0.05, 0.1, 0.2, 5.0)] == [0.0, 0.0, 1.0, 1.0, -1.0]
    assert [linear.force(t, 0, 0) for t in (0.05, 0.2, 5.0)] == pytest.approx([0.5, 0.0, -1.0])
    headerless = tmp_path / "bare.csv"
    headerless.write_text("0,2\n1,3\n")
    assert RecordedForce.from_csv(headerless).forces == (2.0, 3.0)
    named = tmp_path / "named.csv"  # any header of names: it was refused unless it read exactly time,force (break18)
    named.write_text("t_s, force_N\n0,2\n1,3\n")
    assert RecordedForce.from_csv(named).forces == (2.0, 3.0)


@pytest.mark.parametrize(
    "text, match",
    [("time,force\n0,1\n0,2\n", "time\\[1\\]"), ("time,force\n0,x\n", "row 2"), ("", "times/forces"), ("0,1,2\n", "row 1"),
     ("0,x\n1,2\n", "row 1"), ("t_s,f_n\n\n0,1\n1,y\n", "row 4")],  # a row with a number is no header; rows as in the file
)
def test_bad_recordings(tmp_path: pathlib.Path, text: str, match: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ParameterError, match=match):
        RecordedForce.from_csv(path)


def test_missing_recording_file(tmp_path: pathlib.Path) -> None:
    with pytest.raises(ParameterError, match="readable CSV"):
        RecordedForce.from_csv(tmp_path / "nope.csv")


@pytest.mark.parametrize(
    "build, match",
    [
        (lambda: ConstantPush(float("inf")), "level"),
        (lambda: Sinusoid(-1.0, 1.0), "amplitude"),
        (lambda: Sinusoid(1.0, -1.0), "frequency"),
        (lambda: Chirp(1.0, 1.0, 2.0, 0.0), "duration"),
        (lambda: HandModel(-1.0, 0.0), "stiffness"),
        (lambda: StepPush(1.0, -0.5), "start"),
        (lambda: RecordedForce((0.0,), (1.0,), "cubic"), "interpolation"),
        (lambda: ConstantPush("1"), "level"),
    ],
)
def test_parameters_are_validated(build, match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        build()


def test_codes_round_trip_through_0x2010_parameters() -> None:
    for code, cls in OPERATOR_CODES.items():
        if cls is RecordedForce:
            continue
        params = [1.0, 2.0, 0.5, 0.25, 0.0, 3.0]
        model = operator_from_code(code, params)
        assert operator_code(model) == code
        assert list(model.parameters()) == params[: len(model.parameters())]
    with pytest.raises(ParameterError, match="profile only"):
        operator_from_code(6, [0.0] * 6)
    with pytest.raises(ParameterError, match="operator model code"):
        operator_from_code(42, [])


def test_profile_tables(tmp_path: pathlib.Path) -> None:
    assert operator_from_table({"model": "hand", "stiffness": 300.0, "damping": 2.0}) == HandModel(300.0, 2.0)
    (tmp_path / "rec.csv").write_text("0,1\n")
    recorded = operator_from_table({"model": "recorded", "path": "rec.csv", "interpolation": "linear"}, base=tmp_path)
    assert recorded.forces == (1.0,) and recorded.interpolation == "linear"
    with pytest.raises(ParameterError, match=r"operator\.model"):
        operator_from_table({"model": "ghost"})
    with pytest.raises(ParameterError, match="fields of sinusoid"):
        operator_from_table({"model": "sinusoid", "amplitude": 1.0, "frequency": 1.0, "colour": 3})
    with pytest.raises(ParameterError, match="required fields"):
        operator_from_table({"model": "constant"})
