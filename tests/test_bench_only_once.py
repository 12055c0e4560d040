"""``haptic-bus bench --only S --only S`` runs section S once, and its report's title names it once."""

from __future__ import annotations

import json
from pathlib import Path

from haptic_bus.bench import run_bench
from haptic_bus.bench.size import SMOKE


def test_a_section_named_twice_runs_and_is_named_once(tmp_path: Path) -> None:
    result = run_bench(tmp_path, SMOKE, sections=("bus", "bus"))
    assert result["command"] == "haptic-bus bench --smoke --only bus"
    assert (tmp_path / "bench.md").read_text().splitlines()[0] == "# haptic-bus bench --smoke --only bus"
    assert list(json.loads((tmp_path / "bench.json").read_text())["sections"]) == ["bus"]
