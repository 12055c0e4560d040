"""Issues 14, 19 and 26's "Done when", one row per line, read off the sections of one benchmark run.

Each row: which line of the issue (1-5), what is compared, the measured figure with its spread
(median, min-max over >= 5 repeats, or a single count where the figure is one), the target,
and PASS, FAIL or n/a (the section did not run, or a figure it needs is missing).  Nothing is
measured here: every number comes from the section that measured it, in the same run.
"""

from __future__ import annotations

from typing import Any

PASS, FAIL, MISSING = "PASS", "FAIL", "n/a"


def _row(line: int, what: str, measured: str, target: str, passed: bool | None, spread: dict | None = None,
         note: str = "") -> dict[str, Any]:
    return {"line": line, "what": what, "measured": measured, "spread": spread, "target": target,
            "result": MISSING if passed is None else PASS if passed else FAIL, "note": note}


def _spread_text(spread: dict, digits: int = 3) -> str:
    return f"{spread['median']:.{digits}g} ({spread['min']:.{digits}g}-{spread['max']:.{digits}g})"


def _available(sections: dict, name: str) -> dict | None:
    section = sections.get(name)
    return section if section is not None and section.get("available", True) else None


def _passivity(sections: dict) -> list[dict]:
    s = _available(sections, "passivity")
    full = s.get("full_check") if s else None
    if not full:
        return [_row(1, "full check at delay 1 / one 10^4-point numpy T_fund", "-", "<= 5 x", None),
                _row(1, "boundary error against the 40-digit reference", "-", "<= 1e-12", None)]
    worst = full["ratio"]["worst_point"]
    return [
        _row(1, "full check at delay 1 / one 10^4-point numpy T_fund (worst delay-1 point, pairwise)",
             _spread_text(worst), f"<= {full['ratio_target']:g} x", worst["median"] <= full["ratio_target"], worst,
             f"median over the {len(full['points'])} delay-1 points {full['ratio']['median']:.3g}"),
        _row(1, "boundary error (largest passive K and B) against the 40-digit mpmath reference",
             f"{full['boundary_error_max']:.1e}", f"<= {full['boundary_error_target']:g}",
             full["boundary_error_max"] <= full["boundary_error_target"]),
    ]


def _startup(sections: dict) -> list[dict]:
    s = _available(sections, "startup")
    row = s["commands"].get("check --json") if s else None
    if s is None or row is None:
        return [_row(2, "haptic-bus check --json / python -c 'import numpy'", "-", "<= 2.5 x", None)]
    heavy = s.get("check_heavy_imports")
    rows = [_row(2, "haptic-bus check --json wall time / python -c 'import numpy' (pairwise)",
                 _spread_text(row["ratio"]), f"<= {s['ratio_target']:g} x", row["met"], row["ratio"])]
    if heavy is not None:
        rows.append(_row(2, "modules check --json must not import (python -X importtime)",
                         ", ".join(heavy["imported"]) or "none", "none of " + ", ".join(heavy["forbidden"]),
                         not heavy["imported"]))
    return rows


def _realtime(sections: dict) -> list[dict]:
    s = _available(sections, "realtime")
    if s is None:
        return [_row(3, "controller at T = 1 ms, share of a core", "-", "<= 0.12", None)]
    target = s["target"]
    rows = []
    for load, setups in s["runs"].items():
        for name, entry in setups.items():
            what = f"controller core share, {name}, {load}"
            controller = entry.get("controller", {}) if entry.get("available", True) else {}
            share = controller.get("core_share")
            if share is None:
                why = entry.get("reason") or f"run ended: {controller.get('exit_reason')}: {controller.get('error')}"
                rows.append(_row(3, what, "-", f"<= {target['core_share_target']:g}", None, note=why))
                continue
            ended = controller.get("exit_reason", "completed")
            floor = (s.get("issue_26") or {}).get(load, {}).get("floor_core_share")
            notes = ["" if ended == "completed" else f"run ended: {ended}",
                     "" if floor is None else f"python-can alone on the same cycle, this run: {floor:.3g} of a core "
                                              "(issue 26's yardstick)"]
            rows.append(_row(3, what, _spread_text(share, 2), f"<= {target['core_share_target']:g}",
                             share["median"] <= target["core_share_target"], share, "; ".join(n for n in notes if n)))
    default = s["runs"].get("quiet", {}).get("default", {}).get("controller", {})
    untuned = s["runs"].get("quiet", {}).get("untuned", {}).get("controller", {})
    if default.get("lateness_p99_s") and untuned.get("lateness_p99_s"):
        now, before = default["lateness_p99_s"], untuned["lateness_p99_s"]
        rows.append(_row(3, "lateness p99 (us), default set-up, quiet", _spread_text(_scaled(now, 1e6)),
                         f"<= untuned {before['median'] * 1e6:.3g} us", now["median"] <= before["median"],
                         _scaled(now, 1e6)))
    else:
        rows.append(_row(3, "lateness p99, default set-up, quiet", "-", "<= untuned", None))
    if "no_startup_stall" in default:
        rows.append(_row(3, "first 50 cycles' lateness within the run's p99 (default, quiet): max of the first 50 (us)",
                         f"{default['first_cycles_max_late_s'] * 1e6:.3g}",
                         f"<= p99 {default['lateness_s']['p99'] * 1e6:.3g} us", default["no_startup_stall"]))
    else:
        rows.append(_row(3, "no start-up stall", "-", "first 50 within p99", None))
    return rows


def _scaled(spread: dict, factor: float) -> dict:
    return {**spread, "median": spread["median"] * factor, "min": spread["min"] * factor, "max": spread["max"] * factor}


def _loop(sections: dict) -> list[dict]:
    s = _available(sections, "loop")
    floor = s.get("echo_floor") if s else None
    if s is None or not floor:
        return [_row(4, "lock-step loop / python-can threaded echo", "-", ">= 1.5 x", None),
                _row(4, "trajectories lock-step == threaded virtual", "-", "bit-identical", None)]
    same = s["trajectories_identical"]
    return [
        _row(4, "in-process lock-step loop cycles/s / python-can's threaded virtual echo (pairwise)",
             _spread_text(floor["ratio"]), f">= {floor['ratio_target']:g} x", floor["met"], floor["ratio"]),
        _row(4, f"trajectories lock-step vs threaded virtual bus, {same['cycles']} cycles",
             "identical" if same["lockstep_equals_virtual"] else "different", "bit-identical (==)",
             same["lockstep_equals_virtual"]),
    ]


def _soak(sections: dict) -> list[dict]:
    s = _available(sections, "soak")
    if s is None:
        return [_row(5, "soak in virtual time: integer position sum exact", "-", "exact", None),
                _row(5, "soak: resident memory slope", "-", "flat", None)]
    total, memory = s["integer_sum"], s["memory"]
    done = s["cycles"] == s["cycles_asked"] and s["exit_reason"] == "completed"
    return [
        _row(5, f"soak of {s['cycles_asked']:.0e} cycles in virtual time ({s['seconds']:.0f} s): integer position sum "
                "exact, position exact", "exact" if total["exact"] and total["position_exact"] else "NOT exact",
             "exact", done and total["exact"] and total["position_exact"],
             note=f"{s['cycles']:,} cycles, ended {s['exit_reason']}"),
        _row(5, "soak: resident memory slope over the second half (KiB per 10^6 cycles)",
             f"{memory['slope_bytes_per_cycle'] * 1e6 / 1024:.3g}",
             f"growth over the run <= {memory['flat_bytes'] / 2**20:g} MiB",
             done and memory["flat"], note=f"extrapolated over the run: {memory['growth_bytes'] / 2**20:.3g} MiB"),
    ]


def done_when(sections: dict) -> list[dict]:
    """Every row of issue 14's "Done when" from the sections of one run (see the module docstring)."""
    return _passivity(sections) + _startup(sections) + _realtime(sections) + _loop(sections) + _soak(sections)


def _ratio_row(line: int, what: str, ratios: dict | None, key: str) -> dict:
    entry = ratios.get(key) if ratios else None
    if not entry:
        return _row(line, what, "-", "-", None)
    worst = entry["worst_point"]
    return _row(line, what + " (worst delay-1 point, pairwise)", _spread_text(worst), f"<= {entry['target']:g} x",
                worst["median"] <= entry["target"], worst, f"median over the points {entry['median']:.3g}")


def issue_19(sections: dict) -> list[dict]:
    """Issue 19's "Done when" rows: the three costs against one 10^4-point numpy ``T_fund`` side by side
    (the passivity section), ``check --delay 1000`` and ``check --json`` (the start-up section), and the
    boundaries' error against the 40-digit reference."""
    s = _available(sections, "passivity")
    full = s.get("full_check") if s else None
    ratios = full.get("ratios") if full else None
    rows = [
        _ratio_row(1, "gate verdict alone (stability + Re T_fund) / one 10^4-point numpy T_fund", ratios, "verdict"),
        _ratio_row(2, "full check_passivity with limits / one 10^4-point numpy T_fund", ratios, "full_check"),
        _ratio_row(3, "out-of-band exposure (worst pair + 16 aliases) / one 10^4-point numpy T_fund", ratios, "exposure"),
    ]
    start = _available(sections, "startup") or {"commands": {}}
    long_delay = start["commands"].get("check --delay 1000")
    if long_delay is None:
        rows.append(_row(4, "haptic-bus check --delay 1000 wall time", "-", "<= 0.5 s idle", None))
    else:
        wall = long_delay["wall_s"]
        load = start.get("load_average")
        rows.append(_row(4, "haptic-bus check --delay 1000 wall time (fresh process, out-of-band included)",
                         _spread_text(wall), f"<= {start['long_delay_target_s']:g} s idle",
                         wall["median"] <= start["long_delay_target_s"], wall,
                         f"load average {load[0]:.2f}" if load else ""))
    json_row = start["commands"].get("check --json")
    if json_row is None:
        rows.append(_row(5, "haptic-bus check --json / python -c 'import numpy'", "-", "<= 2.5 x", None))
    else:
        rows.append(_row(5, "haptic-bus check --json / python -c 'import numpy' (pairwise)", _spread_text(json_row["ratio"]),
                         f"<= {start['ratio_target']:g} x", json_row["met"], json_row["ratio"]))
    error = full.get("boundary_error_max") if full else None
    rows.append(_row(6, "boundary (largest passive K and B) against the 40-digit mpmath reference",
                     "-" if error is None else f"{error:.1e}", "<= 1e-12", None if error is None else error <= 1e-12))
    return rows


def issue_26(sections: dict) -> list[dict]:
    """Issue 26's timing rows, from the real-time section's default set-up (quiet and beside the hogs):
    the control process's core share over python-can's floor for the same cycle (line 1), its start lateness p99
    and p99.9 over the bare clock's (line 2), each the median of pairs of a run and the bare clock and the floor
    right after it, each pair's figure beside it; its overruns over every pair's cycles (line 2) and the loop delay
    it observed (line 2, quiet, the pairs' median).  Each pair was measured side by side in one run."""
    s = _available(sections, "realtime")
    figures = s.get("issue_26") if s else None
    if not figures:
        return [_row(1, "control process CPU / python-can's floor, T = 1 ms", "-", "<= 1.5 x", None),
                _row(2, "start lateness p99 and p99.9 / the bare clock's", "-", "<= 2 x", None),
                *_preflight_rows(sections)]
    rows = []
    for load in ("quiet", "CPU hog"):
        got = figures.get(load, {})
        ratio = got.get("core_ratio")
        rows.append(_row(1, f"control process CPU / python-can's floor, 1 axis, {load}", _paired_text(got, "core_ratio"),
                         f"<= {figures['core_ratio_target']:g} x",
                         None if ratio is None else ratio <= figures["core_ratio_target"],
                         note="" if ratio is None else f"floor {got['floor_core_share']:.3g} of a core{_unmeasured(got)}"))
        for quantile in ("p99", "p99.9"):
            late = got.get(f"lateness_{quantile}_ratio")
            rows.append(_row(2, f"start lateness {quantile} / the bare clock's, {load}",
                             _paired_text(got, f"lateness_{quantile}_ratio"),
                             f"<= {figures['lateness_ratio_target']:g} x",
                             None if late is None else late <= figures["lateness_ratio_target"],
                             note=_beside_lateness(got, quantile, s)))
        share = got.get("overrun_share")
        rows.append(_row(2, f"overruns, share of cycles, {load}", "-" if share is None else f"{share:.2%}",
                         f"<= {figures['overrun_target']:.1%}", None if share is None else share <= figures["overrun_target"],
                         note="" if share is None else f"of the {got['overrun_cycles']} cycles of every pair's run"))
    axes = s.get("axes", {}) if s else {}
    for load, got in figures.get("three axes", {}).items():
        ratio = got.get("core_ratio")
        rows.append(_row(1, f"control process CPU / python-can's floor, 3 axes ({axes.get('profile')}, its T = "
                            f"{axes.get('period_s', 0) * 1e3:g} ms), {load}",
                         _paired_text(got, "core_ratio"), f"<= {figures['core_ratio_target']:g} x",
                         None if ratio is None else ratio <= figures["core_ratio_target"],
                         note="" if ratio is None else f"floor {got['floor_core_share']:.3g} of a core, writer process "
                                                       f"{got.get('writer_cpu_s')} s{_unmeasured(got)}"))
        late = got.get("lateness_p99_ratio")
        rows.append(_row(2, f"start lateness p99 / the bare clock's, 3 axes, {load}", _paired_text(got, "lateness_p99_ratio"),
                         f"<= {figures['lateness_ratio_target']:g} x",
                         None if late is None else late <= figures["lateness_ratio_target"],
                         note=_beside_lateness(got, "p99", s)))
    delay = figures.get("quiet", {}).get("observed_delay")
    rows.append(_row(2, "loop delay the run observed (assumed + p99 of lateness and input age), quiet, samples",
                     _paired_text(figures.get("quiet", {}), "observed_delay"), f"<= {figures['delay_target']:g}",
                     None if delay is None else delay <= figures["delay_target"]))
    return rows + _preflight_rows(sections)


def _paired_text(got: dict, name: str) -> str:
    """A figure measured over pairs (``name``: ``core_ratio``, ``lateness_p99_ratio``, ...): the median of its pairs,
    each pair's after it in order, ``-`` for one without it (one pair: the figure alone)."""
    each = got.get(f"{name}s")
    if not each or got.get(name) is None:
        return "-"
    spread = f" ({', '.join('-' if r is None else f'{r:.3g}' for r in each)})" if len(each) > 1 else ""
    return f"{got[name]:.3g}{spread}"


def _unmeasured(got: dict) -> str:
    """The pairs a core-share ratio's median leaves out, and why (for the row's note), or nothing."""
    missing = got.get("core_pairs_unmeasured") or []
    if not missing:
        return ""
    return (f"; the median of {len(got['core_ratios']) - len(missing)} of {len(got['core_ratios'])} pairs ("
            + "; ".join(missing) + ")")


def _beside_lateness(got: dict, quantile: str, section: dict | None) -> str:
    """What a lateness row's reader weighs it against: python-can's floor on the same cycle, against the
    same bare clock, and the machine's own gaps measured before the runs (the bare clock meets one CPU's,
    a cycle waiting for its drive two)."""
    said = []
    floor = got.get(f"floor_lateness_{quantile}_ratio")
    if floor is not None:
        said.append(f"python-can's floor on the same cycle: {floor:.3g} x")
    gaps = section.get("host_gaps") if section else None
    if gaps and not isinstance(gaps, str):  # a str: why they were not measured (the section's paragraph says it)
        from haptic_bus.bench.host_gaps import unprivileged

        said.append(("the gaps of a spin not granted SCHED_FIFO (other processes' turns in them)" if unprivileged(gaps)
                     else "the machine's gaps") + " > 1 ms a second, per CPU: "
                    + ", ".join(f"{g['gaps_over_1ms'] / g['seconds']:.2g}" for g in gaps)
                    + f" (longest {max(g['longest_s'] for g in gaps) * 1e3:.2g} ms)")
    return "; ".join(said)


def _preflight_rows(sections: dict) -> list[dict]:
    """Line 3: runs of ``haptic-bus run cia402-handle`` against a fresh ``haptic-bus sim`` that pass
    pre-flight and judge the wall at 1.5 samples or less (every one of them, 20 in the full run)."""
    what = "runs of haptic-bus run cia402-handle against a fresh haptic-bus sim that pass pre-flight, judge at"
    s = _available(sections, "preflight")
    if s is None:
        return [_row(3, f"{what} <= 1.5 samples and exit 0", "-", "all", None)]
    delays = s["judged_delay"]
    outcomes = f"{s['held']} held T, {s['refused']} refused, {s['not_reached']} never reached pre-flight"
    note = outcomes if delays is None else (f"judged at {delays['median']:.3g} samples (median; "
                                            f"{delays['min']:.3g}-{delays['max']:.3g}); {outcomes}")
    planned = s.get("planned", s["count"])
    if s.get("interrupted"):
        note = f"interrupted (Ctrl-C) after {s['count']} of {planned} runs; {note}"
    return [_row(3, f"{what} <= {s['delay_target']:g} samples and exit 0", f"{s['within']} of {s['count']}",
                 f"{planned} of {planned}", None if s.get("interrupted") else s["within"] == s["count"], note=note)]
