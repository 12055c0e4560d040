"""A scene of many walls says a few names and the count of the rest: a profile of 3 000 overlapping walls
printed every name in every contact wall's line and in its refusal (2 x 10^7 characters, break round 16).
Names at most :data:`~haptic_bus.errors.NAMES_SHOWN`, reasons likewise (``--json`` and the decision keep
every one); a refusal's passive intervals are worked out for the reasons shown only."""

from __future__ import annotations

import json
import math
import pathlib

import pytest

import haptic_bus as hb
from haptic_bus.app.cli import main
from haptic_bus.app.profiles import read_profile
from haptic_bus.control.scene import Wall, compile_scene
from haptic_bus.errors import NAMES_SHOWN, ParameterError
from haptic_bus.profile.files import resolve_profile
from haptic_bus.validation import some_names

WALLS = 8


def _walls(tmp_path: pathlib.Path, stiffness: float) -> pathlib.Path:
    """The shipped cia402-handle with its one wall replaced by ``WALLS`` walls 10 um apart, each inside the
    next: ``WALLS`` contact walls, the deepest the sum of them all."""
    text = resolve_profile("cia402-handle").read_text(encoding="utf-8")
    head, tail = text[:text.index("[[scene.objects]]")], text[text.index("[operator_model]"):]
    head = head.replace('bandwidth = "strict"', 'bandwidth = "warn"')  # the margin's reasons alone refuse
    assert 'bandwidth = "warn"' in head
    walls = "".join(f'[[scene.objects]]\nkind = "wall"\nname = "w{i}"\nposition = {0.003 + i * 1e-5:.5f}\nnormal = -1\n'
                    f"stiffness = {stiffness}\ndamping = 10.0\n\n" for i in range(WALLS))
    path = tmp_path / "walls.toml"
    path.write_text(head + walls + tail, encoding="utf-8")
    return path


def test_some_names_shows_a_few_and_counts_the_rest() -> None:
    assert some_names(["a", "b", "c"]) == "a+b+c"
    assert some_names([f"w{i}" for i in range(3000)]) == "w0+w1+w2 and 2997 more"
    assert some_names(("x", "y", "z", "t"), ", ") == "x, y, z and 1 more"


def test_a_check_of_many_refused_walls_names_a_few(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _walls(tmp_path, 1e6)
    code = main(["profiles", "check", str(path)])
    out = capsys.readouterr().out
    assert code == 1
    headers = [line for line in out.splitlines() if line.startswith("--- ")]
    assert headers[:4] == ["--- w0 (summed K, B)", "--- w0+w1 (summed K, B)", "--- w0+w1+w2 (summed K, B)",
                           "--- w0+w1+w2 and 1 more (summed K, B)"]
    assert headers[-1] == f"--- w0+w1+w2 and {WALLS - NAMES_SHOWN} more (summed K, B)" and len(headers) == WALLS
    refused = [line for line in out.splitlines() if line.startswith("  refused: ")]
    assert len(refused) == NAMES_SHOWN + 1 and all("passive K at this B" in line for line in refused[:NAMES_SHOWN])
    assert refused[-1] == f"  refused: and {WALLS - NAMES_SHOWN} more (--json lists every one)"
    code = main(["profiles", "check", str(path), "--json"])
    gate = json.loads(capsys.readouterr().out)["gate"]
    assert code == 1 and len(gate["reasons"]) == WALLS  # every reason; the intervals for the first few only
    assert sum("passive K at this B" in reason for reason in gate["reasons"]) == NAMES_SHOWN


def test_a_run_refused_by_the_gate_says_a_few_reasons_in_one_line(tmp_path: pathlib.Path) -> None:
    decision = read_profile(_walls(tmp_path, 1e6)).judge()
    refusal = hb.Refusal.by_gate(decision, "profile walls.toml", "scene")
    assert len(refusal.reasons) == WALLS and "\n" not in str(refusal)
    assert str(refusal).endswith(f"; and {WALLS - NAMES_SHOWN} more") and str(refusal).count(" is unstable ") == NAMES_SHOWN


def test_an_upload_to_an_object_the_scene_lacks_names_a_few_it_has() -> None:
    scene = compile_scene(Wall(f"w{i}", 0.003 + i * 1e-5, -1, 1500.0, 10.0) for i in range(WALLS))
    with pytest.raises(ParameterError) as refused:
        scene.with_walls({"nope": (1.0, 1.0)})
    assert str(refused.value) == f"scene: object = 'nope' is invalid; allowed: one of w0, w1, w2 and {WALLS - 3} more"


def test_many_overlapping_objects_compile_to_the_exact_sums_rounded_once() -> None:
    """The sweep keeps running exact sums: each interval's K, K * anchor and B are the exact sum of the pieces
    acting there, rounded once (math.fsum's value), many pieces entering and leaving (up to 50 at once), and
    its objects are those pieces' owners, sorted."""
    from haptic_bus.control.scene import Detent, Slot

    few = 16  # the v-walls overlap the 2 * few w-walls: up to 50 pieces at once

    objects = [Wall(f"w{i}", 0.003 + i * 1.1e-5, -1, 1500.0 + 0.1 * i, 10.0 / 3 + i) for i in range(2 * few)]
    objects += [Slot("slot", -0.001, 0.0031, 1e-3, 1e-17), Detent("d", 0.0032, 0.0001, 7.7e4, 0.0)]
    objects += [Wall(f"v{i}", 0.00305 + i * 1e-6, 1, 3.3e-5 * (i + 1), 0.0) for i in range(few)]
    scene = compile_scene(objects)
    pieces = [(start, end, K, anchor, B, obj.name) for obj in objects for start, end, K, anchor, B in obj.pieces()]
    assert max(len(names) for names in scene.contributors) > 2 * few  # many act at once
    for i, names in enumerate(scene.contributors):
        x = (scene.breaks[0] - 1.0 if i == 0 else scene.breaks[i - 1])  # the interval [breaks[i-1], breaks[i])
        acting = [p for p in pieces if p[0] <= x < p[1]]
        assert scene.stiffness[i] == math.fsum(p[2] for p in acting)
        assert scene.stiffness_anchor[i] == math.fsum(p[2] * p[3] for p in acting)
        assert scene.damping[i] == math.fsum(p[4] for p in acting)
        assert names == tuple(sorted({p[5] for p in acting}))


def test_contact_names_in_number_order() -> None:
    walls = [Wall(name=f"w{i}", position=0.003 + i * 1e-6, normal=-1, stiffness=1.0, damping=0.001) for i in range(12)]
    names = max(compile_scene(walls).contacts().values(), key=len)
    assert names == tuple(f"w{i}" for i in range(12))  # was w0, w1, w10, w11, w2, ...: 'w0+w1+w10 and 9 more'
