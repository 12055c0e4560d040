"""Issue 26's CPU ratio over pairs (haptic_bus.bench.thread_tuning.core_pairs): a pair without a ratio (its run
refused at pre-flight, or the floor failed) is left out of the median, and bench.md's row says so, in place and why.
No bench is run: the pairs' figures are given."""

from __future__ import annotations

from collections.abc import Iterator

from haptic_bus.bench import targets, thread_tuning


def run_with(share: float | None) -> dict:
    """A controller run's figures: a median core share, or none (the run refused at pre-flight)."""
    if share is None:
        return {"exit_reason": "pre-flight refused", "error": "the wall is not passive at the delay measured"}
    return {"exit_reason": "completed", "error": None, "core_share": {"median": share}}


def test_a_pair_without_a_ratio_is_shown_in_place_and_named_in_the_rows_note() -> None:
    runs = iter([run_with(None), run_with(0.3)])  # pair 2's run refused; pair 3's run measured
    floors: Iterator[dict] = iter([{"core_share": 0.2}, {"available": False, "reason": "the floor process exited 1"}])
    paired = thread_tuning.core_pairs(run_with(0.26), {"core_share": 0.2}, lambda: next(runs), lambda: next(floors), 3)
    assert [pair["ratio"] for pair in paired["pairs"]] == [0.26 / 0.2, None, None]
    assert paired["ratio"] == 0.26 / 0.2  # the one pair measured
    assert paired["pairs"][1]["run"] == "pre-flight refused"
    assert paired["pairs"][2]["floor"] == "the floor process exited 1"
    figures = thread_tuning._ratios({"controller": run_with(0.26), "core_pairs": paired})
    assert figures["core_ratios"] == [0.26 / 0.2, None, None]
    section = {"issue_26": {"core_ratio_target": 1.5, "lateness_ratio_target": 2.0, "overrun_target": 0.005,
                            "delay_target": 1.5, "quiet": figures}, "axes": {}}
    (row,) = [row for row in targets.issue_26({"realtime": section}) if "1 axis, quiet" in row["what"]
              and "CPU" in row["what"]]
    assert row["measured"] == "1.3 (1.3, -, -)"  # not "1.3" alone, as a single pair of the smoke shows
    assert "the median of 1 of 3 pairs" in row["note"]
    assert "pair 2: its run ended with 'pre-flight refused'" in row["note"]
    assert "pair 3: no floor figure (the floor process exited 1)" in row["note"]


def test_a_further_pair_whose_run_raises_keeps_the_pairs_before_it() -> None:
    def again() -> dict:
        raise RuntimeError("the simulated drive exited")

    paired = thread_tuning.core_pairs(run_with(0.26), {"core_share": 0.2}, again, lambda: {"core_share": 0.2}, 2)
    assert paired["ratio"] == 0.26 / 0.2  # before: the exception left the section's entry unavailable, pair 1 lost
    assert (paired["pairs"][1]["ratio"], paired["pairs"][1]["run"]) == (None, "not run")
    assert paired["pairs"][1]["error"] == "RuntimeError: the simulated drive exited"
