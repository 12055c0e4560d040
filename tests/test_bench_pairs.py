"""Issue 26's ratios over pairs (haptic_bus.bench.pairs.paired_runs): each pair a run, the bare clock and
python-can's floor right after it; each ratio the median of the pairs', each pair's shown in bench.md's row.  A
pair without a core ratio (its run refused at pre-flight, or the floor failed) is left out of that median, and the
row says so, in place and why; a stall of the host in one pair's run moves only that pair's lateness ratio.
No bench is run: the pairs' figures are given."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from haptic_bus.bench import pairs, targets

BARE = {"lateness_s": {"p99": 20e-6, "p99.9": 40e-6}}  # a bare clock's start lateness (s)
ISSUE_26 = {"core_ratio_target": 1.5, "lateness_ratio_target": 2.0, "overrun_target": 0.005, "delay_target": 1.5}


def run_with(share: float | None, p999: float = 60e-6, overruns: int = 0) -> dict:
    """A controller run's figures: a median core share, its lateness (s) and overruns of 1000 cycles, or none (the
    run refused at pre-flight)."""
    if share is None:
        return {"exit_reason": "pre-flight refused", "error": "the wall is not passive at the delay measured"}
    return {"exit_reason": "completed", "error": None, "core_share": {"median": share}, "cycles": 1000,
            "overruns": overruns, "lateness_s": {"p99": 30e-6, "p99.9": p999}, "observed_delay": 1.05}


def rows_of(figures: dict, what: str) -> list[dict]:
    """bench.md's issue-26 rows for one axis, quiet (``figures``), whose text holds ``what``."""
    section = {"issue_26": ISSUE_26 | {"quiet": figures}, "axes": {}}
    return [row for row in targets.issue_26({"realtime": section}) if "quiet" in row["what"] and what in row["what"]]


def test_a_pair_without_a_ratio_is_shown_in_place_and_named_in_the_rows_note() -> None:
    later: Iterator[tuple[dict, dict, dict]] = iter([
        (run_with(None), BARE, {"core_share": 0.2}),  # pair 2's run refused
        (run_with(0.3), BARE, {"available": False, "reason": "the floor process exited 1"})])  # pair 3's floor failed
    paired = pairs.paired_runs((run_with(0.26), BARE, {"core_share": 0.2}), lambda: next(later), 3)
    assert [pair["ratio"] for pair in paired["pairs"]] == [0.26 / 0.2, None, None]
    assert paired["ratio"] == 0.26 / 0.2  # the one pair measured
    assert paired["pairs"][1]["run"] == "pre-flight refused"
    assert paired["pairs"][2]["floor"] == "the floor process exited 1"
    figures = pairs.ratios({"controller": run_with(0.26), "pairs": paired})
    assert figures["core_ratios"] == [0.26 / 0.2, None, None]
    (row,) = rows_of(figures, "CPU")
    assert row["measured"] == "1.3 (1.3, -, -)"  # not "1.3" alone, as a single pair of the smoke shows
    assert "the median of 1 of 3 pairs" in row["note"]
    assert "pair 2: its run ended with 'pre-flight refused'" in row["note"]
    assert "pair 3: no floor figure (the floor process exited 1)" in row["note"]
    # pair 3's run measured its lateness (its floor failed, not its bare clock); pair 2's did not
    assert figures["lateness_p99.9_ratios"] == [1.5, None, 1.5]


def test_a_further_pair_whose_run_raises_keeps_the_pairs_before_it() -> None:
    def again() -> tuple[dict, dict, dict]:
        raise RuntimeError("the simulated drive exited")

    paired = pairs.paired_runs((run_with(0.26), BARE, {"core_share": 0.2}), again, 2)
    assert paired["ratio"] == 0.26 / 0.2  # before: the exception left the section's entry unavailable, pair 1 lost
    assert (paired["pairs"][1]["ratio"], paired["pairs"][1]["run"]) == (None, "not run")
    assert paired["pairs"][1]["error"] == "RuntimeError: the simulated drive exited"


def test_one_pairs_stall_moves_its_own_lateness_ratio_not_the_median() -> None:
    """Five pairs; the third run met a 5 ms stall of the host (its p99.9 of 1000 cycles is that one cycle) and
    overran twice: its ratio is 125 x, the median of the five is the others' 1.5 x, and the overruns count over
    all 5000 cycles."""
    runs = iter([run_with(0.25), run_with(0.26, p999=5e-3, overruns=2), run_with(0.24), run_with(0.25)])
    paired = pairs.paired_runs((run_with(0.25), BARE, {"core_share": 0.2}),
                                       lambda: pairs.measure_pair(lambda: next(runs), lambda: BARE,
                                                                          lambda: {"core_share": 0.2}), 5)
    figures = pairs.ratios({"controller": run_with(0.25), "pairs": paired})
    assert figures["lateness_p99.9_ratios"] == pytest.approx([1.5, 1.5, 125.0, 1.5, 1.5], rel=1e-15)  # one division each
    assert figures["lateness_p99.9_ratio"] == 1.5 and figures["lateness_p99_ratio"] == 1.5
    assert figures["overrun_share"] == 2 / 5000 and figures["overrun_cycles"] == 5000
    assert figures["observed_delay"] == 1.05
    (row,) = rows_of(figures, "p99.9")
    assert row["measured"] == "1.5 (1.5, 1.5, 125, 1.5, 1.5)" and row["result"] == "PASS"
    (row,) = rows_of(figures, "overruns")
    assert row["measured"] == "0.04%" and row["note"] == "of the 5000 cycles of every pair's run"
