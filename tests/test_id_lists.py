"""One reader of node and unit id lists (``haptic_bus.validation.ids_in_order``) for every flag that takes
several: ``run --unit-ids``, ``sim --node-ids``/``--unit-ids``, ``scan --node-ids``/``--unit-ids``.  Ranges
and commas alike, and the same refusal words: ``run --unit-ids 1-3`` was refused where ``scan`` took ranges
(break round 16).  Every refusal of a node or unit id, one or a list, states what is allowed in its table's
one phrase (``drives.cia301.NODE_IDS``, ``drives.modbus.register_map.UNIT_IDS``): they said "1..247",
"a Modbus unit id 1..247", "Modbus unit ids 1..247, whole numbers" and "an integer in [1, 247]"."""

from __future__ import annotations

import argparse
import contextlib
import io
from collections.abc import Callable
from typing import Any

import pytest

import haptic_bus as hb
from drives.canopen.scan import scan_canopen
from drives.cia301 import NODE_IDS
from drives.modbus.drive import ModbusDrive
from drives.modbus.register_map import UNIT_IDS
from drives.modbus.scan import scan_modbus
from drives.safety import SafetySettings
from haptic_bus.app.cli import build_parser, main
from haptic_bus.errors import ParameterError
from sim_drive.setups import node_ids

ALLOWED = "{what} {low}..{high} as N, N-M or a comma-separated list of those, e.g. {low},{b},{c} or {low}-{c}"


def _run_links(args: argparse.Namespace) -> dict[str, Any]:
    """``run``'s link arguments as the command reads them, the test's signal handlers kept (it installs a stop request)."""
    from haptic_bus.app.cli import _prepare_run
    from haptic_bus.app.early_stop import handlers_kept

    with handlers_kept():
        return _prepare_run(args)[3]


def _allowed(what: str, low: int, high: int) -> str:
    return ALLOWED.format(what=what, low=low, high=high, b=low + 1, c=low + 2)


@pytest.mark.parametrize(("argv", "field", "ids"), [
    (["scan", "--modbus", "tcp://127.0.0.1:15174", "--unit-ids", "3,1-2"], "unit_ids", [1, 2, 3]),
    (["scan", "--interface", "virtual", "--channel", "x", "--node-ids", "5-7,0x7f"], "node_ids", [5, 6, 7, 127]),
])
def test_ranges_and_commas_read_the_same_for_every_ids_flag(argv: list[str], field: str, ids: list[int]) -> None:
    assert getattr(build_parser().parse_command(argv), field) == ids  # run: in axis order; scan: the set, sorted


@pytest.mark.parametrize(("text", "ids"), [("1-3", [1, 2, 3]), ("3,1-2", [3, 1, 2])])
def test_run_reads_them_alike_in_axis_order(text: str, ids: list[int]) -> None:
    """run keeps the text until it knows the servers (one: none twice), then reads it with the one reader."""
    args = build_parser().parse_command(["run", "gantry-3d", "--modbus", "tcp://127.0.0.1:47100", "--unit-ids", text])
    assert args.unit_ids == text
    assert _run_links(args)["unit_ids"] == ids


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
    assert code == 2 and err == (f"haptic-bus {argv[0]}: error: {flag} = '1-x' "
                                 f"is invalid; allowed: {_allowed(what, 1, high)}\n"), err


@pytest.mark.parametrize("text", ["3-1", "1-", "-1", "0-2", "126-128", ""])
def test_a_range_out_of_order_or_out_of_bounds_is_refused(text: str) -> None:
    with pytest.raises(ValueError, match=r"CANopen node ids 1\.\.127 as N, N-M"):
        node_ids(text)


def test_distinct_ids_stay_distinct_across_a_range() -> None:
    with pytest.raises(ValueError, match="distinct CANopen node ids"):
        node_ids("5-7,6")


@pytest.mark.parametrize(("argv", "flag", "text", "what", "high", "twice"), [
    (["run", "gantry-3d", "--modbus", "tcp://127.0.0.1:47100"], "--unit-ids", "1-3,2", "Modbus unit ids", 247, 2),
    (["sim", "--modbus", "tcp://127.0.0.1:47100"], "--unit-ids", "1-3,2", "Modbus unit ids", 247, 2),
    (["sim", "--interface", "virtual", "--channel", "x"], "--node-ids", "5-7,0x6", "CANopen node ids", 127, 6),
    (["scan", "--modbus", "tcp://127.0.0.1:47812"], "--unit-ids", "1-3,2", "Modbus unit ids", 247, 2),  # it dropped
    (["scan", "--interface", "udp_multicast", "--channel", "239.74.18.1"], "--node-ids", "1-3,2", "CANopen node ids",
     127, 2),  # the repeat quietly (break18b); refused while the command line is read, before any bus is opened
])
def test_an_id_given_twice_is_named_with_what_was_typed(argv: list[str], flag: str, text: str, what: str, high: int,
                                                        twice: int, capsys: pytest.CaptureFixture[str]) -> None:
    """``run --unit-ids 1-3,2`` with one server named the expanded list ``[1, 2, 3, 2]``; every flag whose ids
    must be distinct now names the text typed and the id given twice, in the same words."""
    code = main([*argv, flag, text])
    err = capsys.readouterr().err
    assert code == 2 and err == (f"haptic-bus {argv[0]}: error: {flag} = {text!r} is invalid; allowed: distinct "
                                 f"{what} 1..{high} ({twice} is given twice)\n"), err


@pytest.mark.parametrize(("servers", "text"), [(1, "1,2"), (1, "1-4"), (3, "1,1")])
def test_a_count_that_is_not_the_profile_s_is_named_with_what_was_typed(servers: int, text: str,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """``run gantry-3d --modbus URL --unit-ids 1,2`` named the expanded list ``[1, 2]`` (the runner's check); the
    count is now checked where the text is read, naming the text and the axes the profile has."""
    urls = [arg for port in range(47104, 47104 + servers) for arg in ("--modbus", f"tcp://127.0.0.1:{port}")]
    code = main(["run", "gantry-3d", *urls, "--unit-ids", text])
    err = capsys.readouterr().err
    assert code == 2 and err == (f"haptic-bus run: error: --unit-ids = {text!r} is invalid; allowed: 3 Modbus unit ids, "
                                 "one per axis (gantry-3d has 3 axes)\n"), err


@pytest.mark.parametrize(("ports", "text", "twice"), [((47105, 47105, 47106), "1,1,2", "unit 1 is given twice at "
                                                      "tcp://127.0.0.1:47105"),
                                                     ((47105, 47106, 47106), "7,3,0x3", "unit 3 is given twice at "
                                                      "tcp://127.0.0.1:47106")])
def test_a_unit_two_axes_share_at_one_url_is_named_with_what_was_typed(ports: tuple[int, ...], text: str, twice: str,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """``run gantry-3d --modbus A --modbus A --modbus B --unit-ids 1,1,2`` named the expanded list ``[1, 1, 2]``
    (the runner's check); the command now names the text typed and the URL with the unit given twice."""
    urls = [arg for port in ports for arg in ("--modbus", f"tcp://127.0.0.1:{port}")]
    code = main(["run", "gantry-3d", *urls, "--unit-ids", text])
    err = capsys.readouterr().err
    assert code == 2 and err == (f"haptic-bus run: error: --unit-ids = {text!r} is invalid; allowed: Modbus unit ids "
                                 f"1..247, none twice at one URL ({twice})\n"), err


def test_one_server_per_axis_may_each_serve_unit_1() -> None:
    """Servers of their own may each hold unit 1: run reads ``1,1,1`` with three ``--modbus`` (none twice on one)."""
    urls = [arg for port in (47101, 47102, 47103) for arg in ("--modbus", f"tcp://127.0.0.1:{port}")]
    args = build_parser().parse_command(["run", "gantry-3d", *urls, "--unit-ids", "1,1,1"])
    assert _run_links(args)["unit_ids"] == [1, 1, 1]



def _refusal(call: Callable[[], object]) -> str:
    """What ``call`` says is allowed when it refuses (ParameterError, or a command's one line on stderr)."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            code = call()
    except ParameterError as refused:
        return refused.allowed
    assert code == 2, err.getvalue()
    return err.getvalue().partition("allowed: ")[2].rstrip("\n")


def _one_axis_run(**link: int | None) -> object:
    """hb.run (hb.run_modbus with ``unit_id=None``) of the one-axis profile over the link ``link`` names."""
    options = hb.RunOptions(0.1, pacing="virtual", live=False)
    if link == {"unit_id": None}:
        return hb.run_modbus(hb.load_profile("cia402-handle"), URL, None, options)  # type: ignore[arg-type]
    bus = URL if "unit_id" in link else {"interface": "virtual", "channel": "x"}
    return hb.run(hb.load_profile("cia402-handle"), bus, options, **link)


URL, CAN = "tcp://127.0.0.1:1", ["--interface", "virtual", "--channel", "x"]  # nothing is reached: refused first
REFUSALS: dict[str, tuple[Callable[[], object], str]] = {
    "status --unit-id 0": (lambda: main(["status", "--modbus", URL, "--unit-id", "0"]), "{units}"),
    "status --unit-id x": (lambda: main(["status", "--modbus", URL, "--unit-id", "x"]),
                           "{units} (decimal, or 0x-hexadecimal)"),
    "sim --unit-id 0": (lambda: main(["sim", "--modbus", URL, "--unit-id", "0"]), "{units}"),
    "run --unit-ids 0-2": (lambda: main(["run", "gantry-3d", "--modbus", URL, "--unit-ids", "0-2"]),
                           "{units} as N, N-M or a comma-separated list of those, e.g. 1,2,3 or 1-3"),
    "hb.run unit_id=0": (lambda: _one_axis_run(unit_id=0), "{units}: the units that answer (0 is broadcast)"),
    "hb.run_modbus unit_id=None": (lambda: _one_axis_run(unit_id=None), "{units}"),
    "ModbusDrive unit_id=0": (lambda: ModbusDrive.from_url(URL, unit_id=0), "{units}"),
    "scan_modbus [0]": (lambda: scan_modbus(URL, [0]), "one or more {units}"),
    "status --node-id 0": (lambda: main(["status", *CAN, "--node-id", "0"]), "{nodes}"),
    "sim --node-id 0": (lambda: main(["sim", *CAN, "--node-id", "0"]), "{nodes}"),
    "hb.run node_id=0": (lambda: _one_axis_run(node_id=0), "{nodes}"),
    "scan_canopen [0]": (lambda: scan_canopen({"interface": "virtual", "channel": "x"}, [0]), "one or more {nodes}"),
    "SafetySettings master_node_id=0": (lambda: SafetySettings(master_node_id=0), "{nodes}, or None (no heartbeat)"),
}


@pytest.mark.parametrize("refused", list(REFUSALS))
def test_every_refusal_of_an_id_states_its_table_s_one_phrase(refused: str) -> None:
    assert (NODE_IDS, UNIT_IDS) == ("CANopen node ids 1..127", "Modbus unit ids 1..247")
    call, allowed = REFUSALS[refused]
    assert _refusal(call) == allowed.format(nodes=NODE_IDS, units=UNIT_IDS)
