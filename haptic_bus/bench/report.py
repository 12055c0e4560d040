"""The benchmark's tables (Markdown) and plots (PNG) from the ``bench.json`` dictionary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from haptic_bus.app.figure_file import save_figure

ERROR_FLOOR = 1e-17  # plotted for an error of exactly 0


def _t(seconds: float | None) -> str:
    """A duration with a unit that keeps 3 significant digits."""
    if seconds is None:
        return "-"
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6)):
        if abs(seconds) >= scale:
            return f"{seconds / scale:.3g} {unit}"
    return f"{seconds / 1e-9:.3g} ns"


def _e(value: float | None) -> str:
    if value is None:
        return "-"
    return "0" if value == 0 else f"{value:.1e}"


def _r(value: float | None) -> str:
    return "-" if value is None else f"{value:.3g}"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def _ts(spread: dict | None) -> str:
    """A timing with its spread: ``median (min-max)`` in the median's unit."""
    if not spread:
        return "-"
    median = spread["median"]
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9)):
        if abs(median) >= scale or unit == "ns":
            return f"{median / scale:.3g} {unit} ({spread['min'] / scale:.3g}-{spread['max'] / scale:.3g})"
    return "-"


def _rs(spread: dict | None, digits: int = 3) -> str:
    """A dimensionless figure (a ratio, a rate) with its spread: ``median (min-max)``."""
    if not spread:
        return "-"
    return f"{spread['median']:.{digits}g} ({spread['min']:.{digits}g}-{spread['max']:.{digits}g})"


def _met(flag: object) -> str:
    return "met" if flag else "NOT met"


def _unavailable(section: dict) -> str | None:
    return None if section.get("available", True) else f"not available: {section.get('reason')}"


def _passivity(s: dict) -> list[str]:
    rows = [[r["method"], _ts(r.get("time_per_check")), _r(r["time_ratio_to_exact"]), _e(r["error_K_median"]),
             _e(r["error_K_max"]), _e(r["error_B_median"]), _e(r["error_B_max"]), str(r["points"])]
            for r in s["methods"]]
    out = [_table(["method", "time/check (min-max)", "x exact", "err K med", "err K max", "err B med", "err B max",
                   "points"], rows)]
    out += ["", f"Relative error of the largest passive K (at the point's B) and B (at its K) against a "
                f"40-digit mpmath reference (all references verified: {s['all_references_verified']}). "
                f"Exact criterion's boundary search: {_ts(s.get('boundary_time', {}).get('exact'))} per boundary. "
                f"Eq. (24) region map over 10^6 (alpha, beta) points: {_ts(s.get('region_map_1e6'))}. "
                f"python-control: {s['control_note']}."]
    full = s.get("full_check")
    if full:
        rows = [[f"m {p['m']:.3g}, b {p['b']:.3g}, K {p['K']:.4g}, B {p['B']:.4g}", _ts(p["full_check_s"]),
                 _ts(p["numpy_t_fund_1e4_s"]), _rs(p["ratio"]), _ts(p["product_t_fund_1e4_s"])] for p in full["points"]]
        out += ["", "Full check at delay 1 (exact verdict + every passive K + every passive B) against one 10^4-point "
                    "numpy evaluation of T_fund, pairwise:", "",
                _table(["delay-1 point", "full check", "numpy T_fund 10^4", "ratio", "product t_fund 10^4"], rows),
                "", f"Worst point's ratio {full['ratio']['max']:.3g} (target <= {full['ratio_target']:g}); largest boundary "
                    f"error {_e(full['boundary_error_max'])} (target <= {full['boundary_error_target']:g}): "
                    f"{_met(full['met'])}."]
    return out


def _plant(s: dict) -> list[str]:
    sc = s["scenario"]
    rows = [[r["method"], _ts(r.get("time_per_simulated")), _r(r["time_ratio_to_exact"]), _e(r["relative_error"])]
            for r in s["methods"]]
    return [_table(["method", "time / simulated s (min-max)", "x exact ZOH", "max rel. error"], rows),
            "", f"m = {sc['m']} kg, b = {sc['b']} N s/m, T = {sc['T']} s (c = {sc['c']:.3g}), delay {sc['delay']}, "
                f"wall K = {sc['K']} N/m, B = {sc['B']} N s/m at {sc['wall_at'] * 1e3:g} mm; push {sc['push_N']} N, "
                f"release at {sc['release_s']} s, {sc['duration_s']} s simulated."]


def _scene(s: dict) -> list[str]:
    rows = [[str(r["objects"]), _ts(r.get("compiled_cycle_p50")), _r(r["compiled_cycle_ratio_to_one_object"]),
             _ts(r.get("naive_cycle_p50")), _r(r["naive_over_compiled_cycle"]), _ts(r.get("compiled_force")),
             _ts(r.get("naive_force"))] for r in s["rows"]]
    tg = s["target"]
    return [_table(["objects", "compiled p50", "x 1 object", "naive p50", "naive/compiled", "force() compiled",
                    "force() naive"], rows),
            "", f"Issue-4 targets: one wall {_t(tg['one_wall_p50_s'])} median (target <= 5 us: {_met(tg['one_wall_met'])}); "
                f"1000 objects / one wall = {tg['thousand_over_one']:.2f} (target <= 1.5: {_met(tg['thousand_met'])})."]


def _space(s: dict) -> list[str]:
    rows = [[str(r["objects"]), str(r["grid_cells"]), f"{r['candidates_per_call']:.2f}", f"{r['contacts_per_call']:.2f}",
             _ts(r["space_force"]), _r(r["space_ratio_to_one_object"]), _ts(r["line_force"]),
             _r(r["line_ratio_to_one_object"]), _ts(r.get("per_object_force")), _r(r.get("per_object_over_compiled")),
             _t(r["compile_space_s"])] for r in s["rows"]]
    return [_table(["objects", "grid cells", "tested/call", "inside/call", "3-D force()", "x 1 object", "1-D force()",
                    "x 1 object", "3-D one by one", "one by one/grid", "compile"], rows), "", s["note"]]


def _layer(s: dict) -> list[str]:
    rows = [[r["profile"], r["timing"], r["layer"], f"{100 * r['lowered']:.2f} %",
             "n/a (no contact)" if r["reached"] is None else f"{100 * r['reached']:.2f} %",
             f"{r['removed_max']:.3g} N", f"{r['least_energy'] * 1e3:+.4g} mJ"] for r in s["rows"]]
    return [_table(["profile", "timing", "layer", "targets lowered", "wall force sent", "most removed from a target",
                    "least port energy (exact)"], rows), "",
            f"{s['seconds']:g} s of virtual time each; adversarial timing seed {s['seed']}; wall force sent: the share "
            "of the force asked of the drive (the wall's, after the force limit) that the targets carried over the "
            "cycles in contact, after the layer (below 100 % by the targets' per-mille rounding where the layer takes "
            "nothing); most removed: the largest force the layer took off one target, at most the profile's force limit "
            "(the drive's clamp holds every target within it)."]


def _loop(s: dict) -> list[str]:
    rows = []
    for link in s["links"].values():
        if link["available"]:
            rows.append([link["label"], _rs(link.get("controller_rate"), 4), _r(link.get("ratio_to_lockstep")),
                         _rs(link.get("bare_rate"), 4), _t(link.get("controller_compute_p50_s"))])
        else:
            rows.append([link["label"], "not available", "-", "-", link["reason"]])
    out = [_table(["link", "controller cycles/s (min-max)", "x lock-step", "bare read/write cycles/s",
                   "controller compute p50"], rows)]
    floor = s.get("echo_floor")
    if floor:
        out += ["", f"Lock-step loop against python-can's two-thread SYNC/TPDO/RPDO echo on its virtual bus "
                    f"({floor['cycles']} cycles a run, pairwise): {_rs(floor['lockstep_rate'], 4)} against "
                    f"{_rs(floor['echo_floor_rate'], 4)} cycles/s, ratio {_rs(floor['ratio'])} (target >= "
                    f"{floor['ratio_target']:g}: {_met(floor['met'])}). Trajectories of the lock-step and the threaded "
                    f"virtual bus from the same start, {s['trajectories_identical']['cycles']} cycles: "
                    f"{'bit-identical' if s['trajectories_identical']['lockstep_equals_virtual'] else 'DIFFERENT'}."]
    modbus = s["links"].get("modbus_tcp", {})
    if modbus.get("bench_cycle"):
        out += ["", "haptic_bus.bench.modbus_poll.bench_cycle: " + "; ".join(
            f"{mode} {_rs(b.get('rate'), 4)} cycles/s ({b['requests_per_cycle']:.2f} requests/cycle, round trip "
            f"p50 {_t(b['round_trip_p50_s'])})" for mode, b in modbus["bench_cycle"].items()) + "."]
    c = s["pdo_codec"]
    out += ["", f"PDO codec, same {c['frames']} frames: hot path {_ts(c.get('hot_path'))}/cycle, canopen generic PDO "
                f"{_ts(c.get('generic'))}/cycle: generic/hot = {c['ratio_generic_over_hot']:.1f}."]
    return out


def _bus(s: dict) -> list[str]:
    mp_, nf = s["mappings"]["minimal"], s["mappings"]["naive_full"]
    out = [_table(["mapping", "TPDO bytes", "RPDO bytes", "bits/axis/cycle", "1 axis + SYNC"], [
        ["minimal", str(mp_["tpdo_frame_bytes"]), str(mp_["rpdo_frame_bytes"]), str(mp_["bits_per_axis"]),
         str(mp_["bits_one_axis_cycle"])],
        ["naive full", str(nf["tpdo_frame_bytes"]), str(nf["rpdo_frame_bytes"]), str(nf["bits_per_axis"]),
         str(nf["bits_one_axis_cycle"])]]), ""]
    rows = [[f"{r['bitrate'] // 1000}k", f"{r['minimal']['load_one_axis']:.1%}", str(r["minimal"]["axes_fit"]),
             _t(r["minimal"]["latency_one_axis_s"]), f"{r['naive_full']['load_one_axis']:.1%}",
             str(r["naive_full"]["axes_fit"]), _t(r["naive_full"]["latency_one_axis_s"])] for r in s["bitrates"]]
    out.append(_table(["bit/s", "minimal: load 1 axis", "axes fit", "latency", "naive: load 1 axis", "axes fit",
                       "latency"], rows))
    out += ["", f"T = {s['period_s'] * 1e3:g} ms, load ceiling {s['load_ceiling']:.0%}; naive/minimal bits per axis "
                f"= {s['naive_over_minimal_bits']:.2f}. Minimal: " + ", ".join(mp_["tpdo_objects"] + mp_["rpdo_objects"])
            + ". Naive full: " + ", ".join(nf["tpdo_objects"] + nf["rpdo_objects"]) + "."]
    meas = s["measured_on_lockstep_bus"]
    if meas.get("available", True):
        out += ["", "BusLoadMeter on the frames actually exchanged (lock-step bus): " + "; ".join(
            f"{k}: {val['meter_bits_median']:.0f} bits/cycle (model {val['model_bits']})" for k, val in meas.items()) + "."]
    return out


def _realtime(s: dict) -> list[str]:
    rows = []
    for load, setups in s["runs"].items():
        for name, entry in setups.items():
            if not entry.get("available", True):
                rows.append([name, load, "not available", "-", "-", "-", "-", "-", entry["reason"]])
                continue
            c, bare = entry["controller"], entry["bare_clock"]
            if "core_share" not in c:
                rows.append([name, load, f"run ended: {c['exit_reason']}", "-", "-", "-", "-", "-", str(c.get("error"))])
                continue
            rows.append([name, load, _rs(c["core_share"], 2), _ts(c["lateness_p50_s"]), _ts(c["lateness_p99_s"]),
                         _t(c["lateness_s"].get("max")), str(c["overruns"]),
                         "yes" if c["no_startup_stall"] else f"NO ({_t(c['first_cycles_max_late_s'])})",
                         f"{_rs(bare['core_share'], 2)}; p99 {_ts(bare['lateness_p99_s'])}"
                         + ("" if c["exit_reason"] == "completed" else f"; run ended: {c['exit_reason']}")])
    out = [_table(["set-up", "load", "core share", "lateness p50", "lateness p99", "max", "overruns", "no start stall",
                   "bare clock: core share; p99"], rows)]
    default = s["runs"]["quiet"].get("default", {}).get("controller", {})
    if default.get("thread_cpu_s"):
        out += ["", "Where the controller process's CPU went (default set-up, quiet; CPU seconds per thread over the "
                    f"{s['duration_s']:g} s run): " + ", ".join(f"{k} {v:.3g}" for k, v in default["thread_cpu_s"].items())
                + ". The control thread (MainThread) owns the bus; the writer process's share is mostly its imports."]
    if isinstance(s.get("host_gaps"), str):
        out += ["", f"The machine's own gaps were not measured: {s['host_gaps']}."]
    elif s.get("host_gaps"):
        out += ["", host_gaps_paragraph(s["host_gaps"])]
    tg, sch = s["target"], s["scheduler"]
    out += ["", f"T = {s['period_s'] * 1e3:g} ms, {s['duration_s']:g} s per run; spreads over {s['segments']} consecutive "
                f"stretches of each run; hog: {s['hog_processes']} busy processes. The simulated drive's threads: "
                f"{default.get('drive_policy')}. This thread outside the runs: policy {sch.get('policy')}, CPUs "
                f"{sch.get('affinity')}, timer slack {sch.get('timer_slack_ns')} ns."]
    if "core_met" in tg:
        out += ["", f"Issue-14 targets (quiet, default set-up): core share {tg['default_core_share']:.3f} (target <= "
                    f"{tg['core_share_target']:g}: {_met(tg['core_met'])}); lateness p99 {_t(tg['default_lateness_p99_s'])} "
                    f"against {_t(tg['untuned_lateness_p99_s'])} untuned ({_met(tg['lateness_no_worse'])}); "
                    f"no start-up stall: {_met(tg['no_startup_stall'])}."]
    return out


def host_gaps_paragraph(gaps: list[dict]) -> str:
    """The probes' figures (:mod:`haptic_bus.bench.host_gaps`) in words: the machine's own gaps where each
    probe spun at ``SCHED_FIFO``, else what they are."""
    from haptic_bus.bench.host_gaps import unprivileged

    policies = ", ".join(dict.fromkeys(g["policy"] for g in gaps))
    if unprivileged(gaps):
        head = (f"Gaps of a thread spinning on each CPU before the runs, at {policies}: every process of its CPU "
                "took turns with it, so they are not the machine's own (a gap is a pause of more than 50 us): ")
    else:
        head = (f"The machine's own gaps, before the runs (a thread spinning at {policies} on each CPU; a gap is a "
                "pause of more than 50 us, which no process here avoids): ")
    return head + "; ".join(_host_gaps(g) for g in gaps) + "."


def _host_gaps(g: dict) -> str:
    """One CPU's gaps (:mod:`haptic_bus.bench.host_gaps`), in words."""
    return (f"CPU {g['cpu']}: {g['gaps']} in {g['seconds']:.2g} s, {g['gaps_over_1ms']} over 1 ms, "
            f"{_t(g['lost_s'])} lost, the longest {_t(g['longest_s'])}")


def _startup(s: dict) -> list[str]:
    rows = [[label, _ts(r["wall_s"]), _ts(r["numpy_import_s"]), _rs(r["ratio"]), _met(r["met"])]
            for label, r in s["commands"].items()]
    costs = ", ".join(f"{c['module']} {_t(c['self_s'])}" for c in s["check_import_costs"])
    out = [_table(["haptic-bus ...", "wall time", "python -c 'import numpy'", "ratio", f"<= {s['ratio_target']:g} x"],
                  rows), "", f"Largest own import times of haptic-bus check (numpy's left out): {costs}."]
    heavy = s.get("check_heavy_imports")
    if heavy:
        out += ["", "Modules check --json should not import, and who imported them first: "
                + ("; ".join(f"{m} (via {' <- '.join(heavy['chains'][m])})" for m in heavy["imported"]) or "none") + "."]
    return out


def _soak(s: dict) -> list[str]:
    total, memory = s["integer_sum"], s["memory"]
    resident = memory["resident_bytes"]
    shown = resident[:: max(1, len(resident) // 10)]
    return [f"{s['cycles']:,} of {s['cycles_asked']:,} cycles in {s['seconds']:.0f} s ({s['cycles_per_s']:.0f} cycles/s), "
            f"ended {s['exit_reason']}" + (f" ({s['error']})" if s.get("error") else "") + ". Integer position sum exact: "
            f"{total['exact']} (position exact: {total['position_exact']}; a float accumulator would have drifted "
            f"{total['float_accumulator_drift_m']:.3g} m). Resident memory sampled every {memory['chunk_cycles']:,} cycles "
            f"({len(resident)} samples; every {max(1, len(resident) // 10)}th shown): "
            + ", ".join(f"{b / 2**20:.1f}" for b in shown)
            + f" MiB; over the second half of the run: spread {memory['second_half_spread_bytes'] / 2**20:.2f} MiB, "
              f"least-squares slope {memory['slope_bytes_per_cycle'] * 1e6 / 1024:.3g} KiB per 10^6 cycles "
              f"({memory['growth_bytes'] / 2**20:.3g} MiB over the run; flat if <= {memory['flat_bytes'] / 2**20:g} MiB)."]


def _preflight(s: dict) -> list[str]:
    from haptic_bus.bench.preflight_runs import reached

    def ending(r: dict) -> str:
        if r["held"] and r["exit"] == 0:
            return ""
        if reached(r) and not r["held"]:
            return r["reason"]
        return r["error"] or r["exit_reason"] or ""

    rows = [[str(k + 1), "-" if r["exit"] is None else str(r["exit"]),
             ("held T" if r["held"] else "refused" if reached(r) else "not reached")
             + (f" ({r['cycles']} cycles)" if r.get("cycles") else ""),
             "-" if r["lateness_p99_s"] is None else _t(r["lateness_p99_s"]),
             "-" if r["delay_added_p99_s"] is None else _t(r["delay_added_p99_s"]),
             "-" if r["judged_delay"] is None or not r["held"] else f"{r['judged_delay']:.3g}",
             ending(r)] for k, r in enumerate(s["runs"])]
    return [s["description"] + ".", "", _table(["run", "exit", "pre-flight", "start lateness p99", "delay added p99",
                                                "loop delay judged (samples)", "refusal, or what ended the run"],
                                               rows), "",
            f"{s['held']} of {s['count']} passed pre-flight, {s['refused']} refused, {s['not_reached']} never "
            f"reached it; {s['within']} of {s['count']} judged the wall at <= {s['delay_target']:g} samples and "
            f"exited 0; {s.get('looked_again', 0)} measured on past the first look's cycles before judging."]


def _done_when(rows: list[dict], issue: int = 14) -> list[str]:
    table = _table(["#", f"Done when (issue {issue})", "measured: median (min-max)", "target", "result"],
                   [[str(r["line"]), r["what"] + (f"; {r['note']}" if r["note"] else ""), r["measured"], r["target"],
                     f"**{r['result']}**"] for r in rows])
    counts = {k: sum(r["result"] == k for r in rows) for k in ("PASS", "FAIL", "n/a")}
    return [table, "", f"{counts['PASS']} PASS, {counts['FAIL']} FAIL, {counts['n/a']} n/a (a section not run or a "
                       "figure missing). Ratios are measured pairwise in this run; spreads over >= 5 repeats."]


_SECTIONS = (
    ("passivity", "1. Passivity check: time per check vs error of the boundary", _passivity),
    ("plant", "2. Plant simulation: time per simulated second vs trajectory error", _plant),
    ("scene", "3. Scene cost: controller compute per cycle", _scene),
    ("loop", "4. The loop: closed-loop cycles per second (virtual time)", _loop),
    ("bus", "5. The bus against its physical limit (worst-case stuffing)", _bus),
    ("realtime", "6. Real time: T = 1 ms, two processes", _realtime),
    ("startup", "7. Start-up of the command line", _startup),
    ("soak", "8. Soak in virtual time", _soak),
    ("space", "9. Scenes in space: force() per call", _space),
    ("layer", "10. The passivity layer: force it takes, nominal and adversarial timing", _layer),
    ("preflight", "11. Pre-flight over fresh processes: haptic-bus run against a fresh haptic-bus sim", _preflight),
)


def markdown(result: dict) -> str:
    """All tables of one benchmark run, with the machine and the command."""
    m = result["machine"]
    v = m["versions"]
    load = m.get("load_average")
    out = [f"# {result['command']}",
           "",
           f"{m['date']}; {m['platform']}; {m['cpu']} ({m['cpu_count']} CPUs"
           + (f", load average {load[0]:.2f} at the start" if load else "") + f"); Python {m['python']}; "
           + ", ".join(f"{k} {val}" for k, val in v.items() if val) + f". Total {result['total_seconds']:.1f} s.",
           "Every timing is the median of at least 5 repeats in this run, with min-max in brackets; ratios compare "
           "figures measured side by side (pairwise where marked)."]
    if "interrupted" in result:
        name = result["interrupted"]
        kept = ", and what of it finished" if name in result["sections"] else ""
        out += ["", f"**Interrupted (Ctrl-C) in section {name}: only the sections before it ran{kept}.**"]
    sections = result["sections"]
    if result.get("done_when"):
        out += ["", "## Issue 14: Done when", "", *_done_when(result["done_when"])]
    if result.get("done_when_19"):
        out += ["", "## Issue 19: Done when", "", *_done_when(result["done_when_19"], 19)]
    if result.get("done_when_26"):
        out += ["", "## Issue 26: Done when (timing)", "", *_done_when(result["done_when_26"], 26)]
    for key, title, render in _SECTIONS:
        s = sections.get(key)
        if s is None:  # not asked for (--only, --soak)
            continue
        out += ["", f"## {title}", ""]
        out += render(s) if s.get("available", True) else [_unavailable(s) or ""]
    return "\n".join(out) + "\n"


def _loglog(ax: Any, points: list[tuple[float, float]], label: str, marker: str = "o", line: bool = False) -> None:
    xs = [p[0] for p in points]
    ys = [max(p[1], ERROR_FLOOR) for p in points]
    ax.loglog(xs, ys, marker=marker, linestyle="-" if line else "none", label=label)


def plots(result: dict, out_dir: Path) -> list[Path]:
    """PNG plots of sections 1-3; returns the paths written."""
    written = []
    sections = result["sections"]
    s = sections.get("passivity")
    if s and s.get("available", True):
        fig, ax = plt.subplots(figsize=(7, 5))
        for r in s["methods"]:
            _loglog(ax, [(r["time_per_check_s"], r["error_max"])], r["method"])
        ax.axhline(ERROR_FLOOR, color="grey", lw=0.5)
        written.append(_label_and_save(fig, ax, ("time per check (s)", "largest relative error of the boundary (K and B)"),
                             "Passivity check: run time vs error", out_dir / "passivity_time_vs_error.png"))
    s = sections.get("plant")
    if s and s.get("available", True):
        fig, ax = plt.subplots(figsize=(7, 5))
        families: dict[str, list] = {}
        for r in s["methods"]:
            families.setdefault(r["family"], []).append((r["time_per_simulated_s"], r["relative_error"]))
        labels = {"exact": "exact ZOH", "euler": "Euler 1..1000 sub-steps", "rk4": "RK4 1..1000 sub-steps",
                  "ivp_RK45": "solve_ivp RK45 (tolerances)", "ivp_DOP853": "solve_ivp DOP853 (tolerances)"}
        for family, points in families.items():
            _loglog(ax, points, labels.get(family, family), line=len(points) > 1)
        written.append(_label_and_save(fig, ax, ("run time per simulated second (s)", "largest relative trajectory error"),
                             "Plant simulation in the closed loop: run time vs error", out_dir / "plant_time_vs_error.png"))
    s = sections.get("scene")
    if s and s.get("available", True):
        fig, ax = plt.subplots(figsize=(7, 5))
        n = [r["objects"] for r in s["rows"]]
        ax.loglog(n, [r["compiled_cycle_p50_s"] for r in s["rows"]], "o-", label="compiled scene (bisect)")
        ax.loglog(n, [r["naive_cycle_p50_s"] for r in s["rows"]], "s-", label="per-object loop (no culling)")
        ax.axhline(5e-6, color="grey", ls="--", lw=0.8, label="issue-4 target, one wall (5 us)")
        written.append(_label_and_save(fig, ax, ("scene objects", "controller compute per cycle, median (s)"), "Scene cost",
                             out_dir / "scene_cost.png"))
    return written


def _label_and_save(fig: Any, ax: Any, labels: tuple[str, str], title: str, path: Path) -> Path:
    """Label the log-log axes (x, y), title, grid and legend them, and write ``fig`` to ``path`` (PNG, 110 dpi)."""
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_title(title)
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)  # beside: on no curve
    fig.tight_layout()
    return save_figure(fig, path, dpi=110, bbox_inches="tight")  # the legend beside the axes too
