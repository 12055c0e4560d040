"""``haptic-bus bench``: files, sections, spreads over >= 5 repeats, finite positive ratios, from one
``--smoke`` run (every section at its smallest: the structure of the output, seconds instead of the
quick run's minutes; no timing thresholds: speed is the benchmark's to report, never a test's to
assert); the refusals before any work (a missing package of the [bench] extra, an unwritable --out)."""

from __future__ import annotations

import itertools
import json
import math
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from haptic_bus.app.preflight import PREFLIGHT_CYCLES, looks_for
from haptic_bus.bench import BENCH_EXTRA, SECTIONS, build_parser, main, run_bench
from haptic_bus.bench.size import FULL, QUICK, SMOKE
from haptic_bus.bench.timing import REPEATS, Spread, paired, time_per_call

pytestmark = pytest.mark.slow  # the smoke bench behind these tests: 23-24 s, 18-21 s of CPU (pytest -n 0, idle) on this
# 2-core machine; about half of it is the 27 processes it starts (its three-axis run has no ball: thread_tuning.axes_profile)

SmokeRun = tuple[Path, dict[str, Any]]
REPO = Path(__file__).resolve().parents[1]


def _finite_positive(value: object) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


def _spreads(node: object, path: str = "") -> Iterator[tuple[str, dict[str, Any]]]:
    """Every ``{"median", "min", "max", "repeats"}`` dictionary in ``node``, with where it is."""
    if isinstance(node, dict):
        if {"median", "min", "max", "repeats"} <= set(node):
            yield path, node
        for key, value in node.items():
            yield from _spreads(value, f"{path}.{key}")
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _spreads(value, f"{path}[{i}]")


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory: pytest.TempPathFactory) -> SmokeRun:
    out = tmp_path_factory.mktemp("bench")
    return out, run_bench(out, size=SMOKE, progress=False)


def test_smoke_bench_writes_every_file(smoke_run: SmokeRun) -> None:
    out, _ = smoke_run
    for name in ("bench.json", "bench.md", "passivity_time_vs_error.png", "plant_time_vs_error.png", "scene_cost.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    text = (out / "bench.md").read_text()
    for heading in ("## Issue 14: Done when", "## 1.", "## 2.", "## 3.", "## 4.", "## 5.", "## 6.", "## 7.", "## 8."):
        assert heading in text


def test_every_done_when_line_of_issue_14_is_a_row_with_a_verdict(smoke_run: SmokeRun) -> None:
    _, result = smoke_run
    rows = result["done_when"]
    assert {r["line"] for r in rows} == {1, 2, 3, 4, 5}
    for row in rows:
        assert row["result"] in ("PASS", "FAIL", "n/a") and row["target"], row
        if row["spread"] is not None:  # a timing ratio: at least 5 repeats behind it
            assert row["spread"]["repeats"] >= REPEATS and row["spread"]["min"] <= row["spread"]["max"], row
    lines_with_a_figure = {r["line"] for r in rows if r["result"] != "n/a"}
    assert {1, 2, 4, 5} <= lines_with_a_figure  # no external link needed for these
    floors = {load: got.get("floor_core_share") for load, got in result["sections"]["realtime"]["issue_26"].items()
              if isinstance(got, dict) and "floor_core_share" in got}
    checked = 0
    for row in (r for r in rows if r["what"].startswith("controller core share") and r["result"] != "n/a"):
        load = row["what"].rsplit(", ", 1)[1]  # the absolute 0.12 of a core beside python-can's own share this run
        if floors.get(load) is not None:  # the floor of the pairs whose default run cycled
            assert f"python-can alone on the same cycle, this run: {floors[load]:.3g} of a core" in row["note"], row
            checked += 1
    assert checked or not floors, (floors, rows)  # a floor measured is beside its load's rows (at least the default's)


def test_every_timing_line_of_issue_26_is_a_row_with_a_verdict(smoke_run: SmokeRun) -> None:
    """CPU against python-can's floor, lateness against the bare clock, overruns, for both loads, and
    the loop delay observed when quiet: a figure where the run cycled, "n/a" where pre-flight refused it.
    Nine rows for one axis (both loads), two for three axes (the smoke size runs them quiet only), and
    pre-flight over fresh processes (line 3: how many of the runs passed it, of how many)."""
    _, result = smoke_run
    rows = result["done_when_26"]
    assert len(rows) == 12 and {r["line"] for r in rows} == {1, 2, 3}
    assert sum("3 axes" in r["what"] for r in rows) == 2
    *timing, preflight = rows
    for row in timing:
        assert row["result"] in ("PASS", "FAIL", "n/a") and row["target"].startswith("<="), row
        assert (row["result"] == "n/a") == (row["measured"] == "-"), row
    section = result["sections"]["preflight"]
    assert preflight["line"] == 3 and preflight["target"] == "1 of 1"
    assert preflight["measured"] == f"{section['within']} of 1"
    assert preflight["result"] == ("PASS" if section["within"] == 1 else "FAIL")


def test_pre_flight_over_fresh_processes_reads_each_runs_verdict(smoke_run: SmokeRun) -> None:
    """The smoke's one ``haptic-bus run`` against a fresh ``haptic-bus sim``: it passed pre-flight and
    names the loop delay it judged at (at least the one sample the drive adds), or it was refused,
    exit 1, naming the period this machine held."""
    out, result = smoke_run
    (entry,) = result["sections"]["preflight"]["runs"]
    if entry["held"]:
        assert entry["exit"] == 0 and entry["judged_delay"] >= 1.0, entry
    else:
        assert entry["exit"] == 1 and "this machine holds T >=" in entry["reason"], entry
    # the cycles it judged: the first look's, or a later look's too (haptic_bus.app.preflight.looks_for)
    assert entry["cycles"] in looks_for(PREFLIGHT_CYCLES), entry
    assert result["sections"]["preflight"]["looked_again"] == (entry["cycles"] > PREFLIGHT_CYCLES)
    assert "## 11. Pre-flight over fresh processes" in (out / "bench.md").read_text()


def test_smoke_bench_json_has_every_section_and_the_machine(smoke_run: SmokeRun) -> None:
    out, _ = smoke_run
    data = json.loads((out / "bench.json").read_text())
    assert data["size"] == "smoke" and data["command"] == "haptic-bus bench --smoke"
    machine = data["machine"]
    assert machine["cpu_count"] >= 1 and machine["python"] and machine["date"]
    for package in ("numpy", "scipy", "canopen", "python-can", "pymodbus", "control"):
        assert package in machine["versions"]
    assert set(SECTIONS) == set(data["sections"])
    for name in ("passivity", "plant", "scene", "bus", "realtime", "startup"):  # no external link involved
        assert data["sections"][name]["available"], data["sections"][name].get("reason")


def test_every_timing_is_a_spread_over_at_least_five_repeats(smoke_run: SmokeRun) -> None:
    _, result = smoke_run
    found = list(_spreads(result["sections"]))
    assert len(found) > 40
    for where, spread in found:
        assert spread["repeats"] >= REPEATS, where
        assert spread["min"] <= spread["median"] <= spread["max"], where


def test_smoke_bench_ratios_are_finite_and_positive(smoke_run: SmokeRun) -> None:
    _, result = smoke_run
    s = result["sections"]
    methods = {m["key"]: m for m in s["passivity"]["methods"]}
    assert {"closed_form", "exact", "grid_100", "grid_1000"} == set(methods)  # the smoke's grids, no python-control
    for m in methods.values():
        assert _finite_positive(m["time_per_check_s"]) and _finite_positive(m["time_ratio_to_exact"])
        assert math.isfinite(m["error_max"]) and m["error_max"] >= 0
    assert s["passivity"]["all_references_verified"]
    full = s["passivity"]["full_check"]
    assert full["points"] and _finite_positive(full["ratio"]["max"]) and math.isfinite(full["boundary_error_max"])
    for point in full["points"]:  # the floor computes the same T_fund as the product (to 1e-6: it is naive numpy)
        assert point["numpy_vs_product_max_relative"] < 1e-6
    for row in s["plant"]["methods"]:
        assert _finite_positive(row["time_ratio_to_exact"]) and math.isfinite(row["relative_error"])
    for row in s["scene"]["rows"]:
        assert _finite_positive(row["compiled_cycle_ratio_to_one_object"]) and _finite_positive(row["naive_over_compiled_cycle"])
    loop = s["loop"]
    assert loop["links"]["lockstep"]["available"], loop["links"]["lockstep"].get("reason")
    for link in loop["links"].values():
        if link["available"]:
            assert _finite_positive(link["controller_cycles_per_s"]) and _finite_positive(link["ratio_to_lockstep"])
        else:
            assert link["reason"]
    assert _finite_positive(loop["echo_floor"]["ratio"]["median"])
    assert loop["trajectories_identical"]["lockstep_equals_virtual"]  # deterministic: the same frames, the same plant
    assert _finite_positive(loop["pdo_codec"]["ratio_generic_over_hot"])
    assert _finite_positive(s["bus"]["naive_over_minimal_bits"])
    assert s["bus"]["mappings"]["minimal"]["bits_per_axis"] == 210  # (55 + 60) + (55 + 40), DESIGN 6
    for load in ("quiet", "CPU hog"):
        for name, entry in s["realtime"]["runs"][load].items():
            assert entry.get("available", True) or entry["reason"], name
            if "controller" in entry and "core_share" in entry["controller"]:
                assert _finite_positive(entry["controller"]["core_share"]["median"]) and entry["controller"]["cycles"] > 0
        floor = s["realtime"]["runs"][load]["default"].get("floor", {})
        if floor.get("available", True):  # python-can alone, the same frames, beside the default run
            assert _finite_positive(floor["core_share"]) and floor["cycles"] > 0 and floor["lateness_s"]["p99"] >= 0
            controller = s["realtime"]["runs"][load]["default"]["controller"]
            (pair,) = s["realtime"]["runs"][load]["default"]["pairs"]["pairs"]  # one pair in the smoke: that run
            assert pair["floor_core_share"] == floor["core_share"]
            if "core_share" in controller:
                assert pair["core_share"] == controller["core_share"]["median"]
                assert pair["ratio"] == controller["core_share"]["median"] / floor["core_share"]
                bare = s["realtime"]["runs"][load]["default"]["bare_clock"]["lateness_s"]  # measured right after the run
                assert pair["lateness_p99.9_ratio"] == controller["lateness_s"]["p99.9"] / bare["p99.9"]
                assert (pair["cycles"], pair["overruns"]) == (controller["cycles"], controller["overruns"])
            else:  # a run refused at pre-flight (a loaded machine's hogged run: 6 of 200 cycles over T): no ratio, and why
                assert pair["core_share"] is None and pair["ratio"] is None
                assert (pair["run"], pair["error"]) == (controller["exit_reason"], controller["error"]) and pair["error"]
    gaps = s["realtime"]["host_gaps"]  # the machine's own gaps, one spinning process per CPU, 0.2 s each (smoke)
    assert [g["cpu"] for g in gaps] == sorted(os.sched_getaffinity(0))
    for g in gaps:  # spun 0.2 s in all, ending at the first reading past it (a gap, or under 50 us, later)
        assert 0.2 <= g["seconds"] <= 0.2 + max(g["longest_s"], 50e-6) and 0 <= g["gaps_over_1ms"] <= g["gaps"]
        assert g["longest_s"] <= g["lost_s"] <= g["seconds"] and (g["gaps"] == 0) == (g["lost_s"] == 0)
    for label, row in s["startup"]["commands"].items():
        assert _finite_positive(row["ratio"]["median"]), label
    assert s["startup"]["check_import_costs"]


def test_a_short_soak_reports_an_exact_sum_and_the_memory_it_sampled(smoke_run: SmokeRun) -> None:
    from haptic_bus.bench.soak import SAMPLES

    result = smoke_run[1]["sections"]["soak"]  # the smoke's soak: 2 000 cycles
    assert result["cycles"] == result["cycles_asked"] == 2_000 and result["exit_reason"] == "completed"
    assert result["integer_sum"]["exact"] and result["integer_sum"]["position_exact"]
    memory = result["memory"]
    assert len(memory["resident_bytes"]) == len(memory["at_cycles"]) == SAMPLES + 1  # before, and after each chunk
    assert memory["at_cycles"][-1] == 2_000 and math.isfinite(memory["slope_bytes_per_cycle"])


# ----------------------------------------------------------------------------- no bench run needed

def test_the_soak_reports_between_its_ten_ticks_at_most_every_progress_interval(monkeypatch: pytest.MonkeyPatch) -> None:
    """``--soak 1e9`` ticked ten times in hours; between its ten ticks (each tenth of the run, the bar
    advanced) the count now comes at least every PROGRESS_SECONDS of wall time.  The wall clock is a fake
    one, 1 s a reading, two readings a piece, so the reports depend on no machine's speed: a report comes
    at the first piece's end at least PROGRESS_SECONDS after the last, so no two are more than
    PROGRESS_SECONDS + 2 s (one piece) apart."""
    import types

    from haptic_bus.bench import soak

    clock = [0.0]

    def perf_counter() -> float:
        clock[0] += 1.0
        return clock[0]

    monkeypatch.setattr(soak, "time", types.SimpleNamespace(perf_counter=perf_counter))
    reports: list[tuple[str, bool, float]] = []

    def tick(label: str, *, advance: bool = True) -> None:
        reports.append((label, advance, clock[0]))

    result = soak.run(2_000, tick)  # pieces of one 20-cycle chunk each (the next memory sample), 2 s each
    advanced = [label for label, advance, _ in reports if advance]
    assert advanced == [f"soak: {n:,} of 2,000 cycles" for n in range(200, 2_001, 200)]  # one a tenth, the last at the end
    assert len(reports) > len(advanced)  # reports between the ticks
    assert all(0 < b - a <= soak.PROGRESS_SECONDS + 2 for (_, _, a), (_, _, b) in itertools.pairwise(reports))
    assert result["memory"]["at_cycles"] == list(range(0, 2_001, 20))  # the memory samples as before: each chunk


def test_the_soak_sizes_its_pieces_from_the_rate_so_far() -> None:
    """Half a progress interval's worth of cycles at the rate measured, FIRST_PIECE before any, 1..left."""
    from haptic_bus.bench.soak import FIRST_PIECE, PROGRESS_SECONDS, piece_cycles

    assert piece_cycles(0, 0.0, 10**9) == FIRST_PIECE and piece_cycles(0, 0.0, 7) == 7
    assert piece_cycles(30_000, 1.0, 10**9) == int(30_000 * PROGRESS_SECONDS / 2)  # 30 000 cycles/s: 5 s of them
    assert piece_cycles(1, 1e6, 10**9) == 1 and piece_cycles(30_000, 1.0, 99) == 99


def test_spreads_and_pairs() -> None:
    spread = Spread.of([3.0, 1.0, 2.0, 5.0, 4.0])
    assert (spread.median, spread.low, spread.high, spread.repeats) == (3.0, 1.0, 5.0, 5)
    assert spread.rate(6.0) == Spread(2.0, 1.2, 6.0, 5)  # 6 per second: the slowest run is the lowest rate
    calls = iter(range(1, 100))
    first, second, ratio = paired(lambda: float(next(calls)), lambda: 1.0, repeats=2)
    assert first.repeats == second.repeats == ratio.repeats == REPEATS  # never fewer than 5
    assert ratio.low == 1.0 and ratio.high == 5.0  # pairs (1, 1), (2, 1), .., (5, 1)
    assert time_per_call(lambda: None, min_ns=10_000).repeats == REPEATS


def test_bench_cli_rejects_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--only", "nonsense"]) == 2
    assert "invalid choice" in capsys.readouterr().err
    assert main(["--soak", "0"]) == 2
    assert "1..1e9" in capsys.readouterr().err


def test_the_soak_option_defaults_to_ten_million_cycles() -> None:
    parser = build_parser()
    assert parser.parse_args([]).soak is None
    assert parser.parse_args(["--soak"]).soak == 10_000_000
    assert parser.parse_args(["--soak", "2e4"]).soak == 20_000


def test_ctrl_c_ends_the_bench_with_130_and_one_line_on_stderr(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import haptic_bus.bench as bench

    def interrupted(size: Any, tick: Any) -> dict:
        raise KeyboardInterrupt

    monkeypatch.setattr(bench, "_runner", lambda name: interrupted)
    assert main(["--quick", "--no-progress", "--only", "bus", "--out", str(tmp_path)]) == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "interrupted in section bus" in err and "Traceback" not in err
    assert json.loads((tmp_path / "bench.json").read_text())["interrupted"] == "bus"  # what ran is still written


def test_the_sizes_and_their_flags() -> None:
    parser = build_parser()
    assert parser.parse_args([]).size is FULL
    assert parser.parse_args(["--quick"]).size is QUICK and parser.parse_args(["--smoke"]).size is SMOKE
    assert QUICK.pick(1, 2, 3) == 2


def test_quick_and_smoke_exclude_each_other(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--quick", "--smoke"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_the_bench_extra_is_pyprojects(tmp_path: Path) -> None:
    import re
    import tomllib

    extra = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]["bench"]
    assert sorted(re.match(r"[A-Za-z0-9_.-]+", requirement)[0] for requirement in extra) == sorted(BENCH_EXTRA.values())


@pytest.mark.parametrize("module", sorted(BENCH_EXTRA))
def test_a_missing_package_of_the_extra_is_one_line_and_exit_2_before_any_work(
        module: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, module, None)  # import now raises ImportError, as where it is not installed
    out = tmp_path / "out"
    assert main(["--smoke", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == (f"haptic-bus bench: error: the [bench] extra is missing: {BENCH_EXTRA[module]}; install it with: "
                   "pip install 'haptic_bus[bench]' (from a checkout: pip install -e '.[bench]')\n")
    assert not out.exists()  # checked before any work


@pytest.mark.parametrize("where", ["a file", "inside a file"])
def test_an_unwritable_out_is_one_line_and_exit_2(where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    afile = tmp_path / "afile"
    afile.write_text("kept\n")
    out = afile if where == "a file" else afile / "bench"
    assert main(["--smoke", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"haptic-bus bench: error: --out = '{out}' is invalid; allowed: a folder this user can "
                          "create and write (") and err.count("\n") == 1 and "Traceback" not in err
    assert afile.read_text() == "kept\n"
