"""One reader of node and unit id lists (``haptic_bus.validation.ids_in_order``) for every flag that takes
several: ``run --unit-ids``, ``sim --node-ids``/``--unit-ids``, ``scan --node-ids``/``--unit-ids``.  Ranges
and commas alike, and the same refusal words: ``run --unit-ids 1-3`` was refused where ``scan`` took ranges
(break round 16)."""

from __future__ import annotations

import pytest

from haptic_bus.app.cli import build_parser, main
from sim_drive.setups import node_ids

ALLOWED = "{what} {low}..{high} as N, N-M or a comma-separated list of those, e.g. {low},{b},{c} or {low}-{c}"


def _allowed(what: str, low: int, high: int) -> str:
    return ALLOWED.format(what=what, low=low, high=high, b=low + 1, c=low + 2)


@pytest.mark.parametrize(("argv", "field", "ids"), [
    (["run", "gantry-3d", "--modbus", "tcp://127.0.0.1:15174", "--unit-ids", "1-3"], "unit_ids", [1, 2, 3]),
    (["run", "gantry-3d", "--modbus", "tcp://127.0.0.1:15174", "--unit-ids", "3,1-2"], "unit_ids", [3, 1, 2]),
    (["scan", "--modbus", "tcp://127.0.0.1:15174", "--unit-ids", "3,1-2"], "unit_ids", [1, 2, 3]),
    (["scan", "--interface", "virtual", "--channel", "x", "--node-ids", "5-7,0x7f"], "node_ids", [5, 6, 7, 127]),
])
def test_ranges_and_commas_read_the_same_for_every_ids_flag(argv: list[str], field: str, ids: list[int]) -> None:
    assert getattr(build_parser().parse_command(argv), field) == ids  # run: in axis order; scan: the set, sorted


def test_sim_reads_them_alike() -> None:
    assert node_ids("5-7") == [5, 6, 7] and node_ids("7,5-6") == [7, 5, 6]


@pytest.mark.parametrize(("argv", "what", "high"), [
    (["run", "gantry-3d", "--modbus", "tcp://127.0.0.1:15174", "--unit-ids", "1-x"], "Modbus unit ids", 247),
    (["scan", "--modbus", "tcp://127.0.0.1:15174", "--unit-ids", "1-x"], "Modbus unit ids", 247),
    (["scan", "--interface", "virtual", "--channel", "x", "--node-ids", "1-x"], "CANopen node ids", 127),
])
def test_a_list_that_cannot_be_is_refused_in_the_same_words(argv: list[str], what: str, high: int,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    flag = argv[-2]
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2 and err == (f"haptic-bus {argv[0]}: error: argument {flag}: {flag[2:].replace('-', ' ')} = '1-x' "
                                 f"is invalid; allowed: {_allowed(what, 1, high)}\n"), err


@pytest.mark.parametrize("text", ["3-1", "1-", "-1", "0-2", "126-128", ""])
def test_a_range_out_of_order_or_out_of_bounds_is_refused(text: str) -> None:
    with pytest.raises(ValueError, match=r"CANopen node ids 1\.\.127 as N, N-M"):
        node_ids(text)


def test_distinct_ids_stay_distinct_across_a_range() -> None:
    with pytest.raises(ValueError, match="distinct CANopen node ids"):
        node_ids("5-7,6")
