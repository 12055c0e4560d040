"""``haptic-bus bench --quick``: files, sections and finite positive ratios (no timing thresholds)."""

from __future__ import annotations

import json
import math

import pytest

from haptic_bus.bench import SECTIONS, main, run_bench


def _finite_positive(value: object) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("bench")
    return out, run_bench(out, quick=True, progress=False)


@pytest.mark.slow
def test_quick_bench_writes_every_file(quick_run) -> None:
    out, result = quick_run
    for name in ("bench.json", "bench.md", "passivity_time_vs_error.png", "plant_time_vs_error.png", "scene_cost.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    text = (out / "bench.md").read_text()
    for heading in ("## 1.", "## 2.", "## 3.", "## 4.", "## 5.", "## 6."):
        assert heading in text


@pytest.mark.slow
def test_quick_bench_json_has_every_section_and_the_machine(quick_run) -> None:
    out, _ = quick_run
    data = json.loads((out / "bench.json").read_text())
    assert data["quick"] is True
    machine = data["machine"]
    assert machine["cpu_count"] >= 1 and machine["python"] and machine["date"]
    for package in ("numpy", "scipy", "canopen", "python-can", "pymodbus", "control"):
        assert package in machine["versions"]
    assert set(SECTIONS) <= set(data["sections"])
    for name in ("passivity", "plant", "scene", "bus", "realtime"):  # no external link involved
        assert data["sections"][name]["available"], data["sections"][name].get("reason")


@pytest.mark.slow
def test_quick_bench_ratios_are_finite_and_positive(quick_run) -> None:
    _, result = quick_run
    s = result["sections"]
    methods = {m["key"]: m for m in s["passivity"]["methods"]}
    assert {"closed_form", "exact", "grid_100", "grid_1000000"} <= set(methods)
    for m in methods.values():
        assert _finite_positive(m["time_per_check_s"]) and _finite_positive(m["time_ratio_to_exact"])
        assert math.isfinite(m["error_max"]) and m["error_max"] >= 0
    assert s["passivity"]["all_references_verified"]
    for row in s["plant"]["methods"]:
        assert _finite_positive(row["time_ratio_to_exact"]) and math.isfinite(row["relative_error"])
    for row in s["scene"]["rows"]:
        assert _finite_positive(row["compiled_cycle_ratio_to_one_object"]) and _finite_positive(row["naive_over_compiled_cycle"])
    loop = s["loop"]
    assert loop["links"]["virtual"]["available"], loop["links"]["virtual"].get("reason")
    for link in loop["links"].values():
        if link["available"]:
            assert _finite_positive(link["controller_cycles_per_s"]) and _finite_positive(link["ratio_to_virtual"])
        else:
            assert link["reason"]
    assert _finite_positive(loop["pdo_codec"]["ratio_generic_over_hot"])
    assert _finite_positive(s["bus"]["naive_over_minimal_bits"])
    assert s["bus"]["mappings"]["minimal"]["bits_per_axis"] == 210  # (55 + 60) + (55 + 40), DESIGN 6
    assert s["realtime"]["cycles"] > 0 and s["realtime"]["lateness_s"]


def test_bench_cli_rejects_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--only", "nonsense"]) == 2
    assert "invalid choice" in capsys.readouterr().err
