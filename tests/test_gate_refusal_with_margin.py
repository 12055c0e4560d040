"""A wall the gate refuses for its safety margin is told what passes *with* that margin, not only
what is passive (breaker11b: cia402-handle's end stop at K = 16000 N/m, B = 10 N s/m, margin 0.85 <
2 N s/m, was told "passive K at this B: [0, 16911.1] N/m", a range its own K lies in)."""

from __future__ import annotations

import pathlib
import re

import pytest

from haptic_bus.app.profiles import Profile, read_profile
from haptic_bus.profile.files import resolve_profile


def _with_wall(tmp_path: pathlib.Path, stiffness: float, damping: float) -> Profile:
    """The shipped cia402-handle (m 1 kg, b 20 N s/m, T 1 ms, delay 1, safety margin 2 N s/m) with
    its end stop at ``stiffness`` N/m and ``damping`` N s/m, the bandwidth rule a warning (the
    margin alone decides)."""
    text = resolve_profile("cia402-handle").read_text(encoding="utf-8").replace('bandwidth = "strict"', 'bandwidth = "warn"')
    text = re.sub(r"^stiffness = 1500\.0", f"stiffness = {stiffness!r}", text, count=1, flags=re.MULTILINE)
    text = re.sub(r"^damping = 10\.0", f"damping = {damping!r}", text, count=1, flags=re.MULTILINE)
    path = tmp_path / f"wall-{stiffness}-{damping}.toml"
    path.write_text(text, encoding="utf-8")
    profile = read_profile(path)
    assert isinstance(profile, Profile)
    return profile


@pytest.mark.parametrize(("K", "B", "named", "bound"), [
    (16000.0, 10.0, r"with margin >= 2 N s/m: K at this B \[0, ([0-9.]+)\] N/m", "K"),  # passive, short of the margin
    (1500.0, 40.0, r"with margin >= 2 N s/m: K at this B none, B at this K \[0, ([0-9.]+)\] N s/m", "B"),  # not passive
])
def test_the_refusal_names_what_passes_the_gate(tmp_path: pathlib.Path, K: float, B: float, named: str,
                                                bound: str) -> None:
    decision = _with_wall(tmp_path, K, B).judge()
    assert not decision.accepted
    found = re.search(named, " ".join(decision.reasons))
    assert found is not None, decision.reasons
    largest = float(found.group(1))  # printed to 6 significant digits: 1e-5 relative either side decides
    below, above = largest * (1 - 1e-5), largest * (1 + 1e-5)
    walls = [(below, B), (above, B)] if bound == "K" else [(K, below), (K, above)]
    assert [_with_wall(tmp_path, *wall).judge().accepted for wall in walls] == [True, False]
