"""The manual's error tree (docs/_ext/error_tree.py, drawn at build time): every error class of the three
packages once, under its first base, below the one root of haptic_bus.errors and drives.errors."""

from __future__ import annotations

import importlib.util
import pathlib
import types

from haptic_bus.errors import HapticBusError

EXTENSION = pathlib.Path(__file__).resolve().parents[1] / "docs" / "_ext" / "error_tree.py"


def _extension() -> types.ModuleType:
    """The Sphinx extension's module, loaded from its file (docs/_ext is no package)."""
    spec = importlib.util.spec_from_file_location("error_tree", EXTENSION)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _below(cls: type) -> set[type]:
    found = set()
    for sub in cls.__subclasses__():
        if sub.__module__.split(".")[0] in ("haptic_bus", "drives", "sim_drive"):
            found |= {sub, *_below(sub)}
    return found


def test_the_tree_draws_every_error_once_under_its_first_base() -> None:
    tree = _extension()
    rows = tree.tree_lines()  # imports every module first
    assert tree.roots() == [HapticBusError]
    drawn = [column.split("-- ")[-1].split(" (")[0] for column, _, _ in rows if column]
    every = {HapticBusError} | _below(HapticBusError)
    assert sorted(drawn) == sorted(cls.__name__ for cls in every)  # once each: a second parent is a note, not a row
    assert "ParameterError (ValueError)" in tree.tree_text() and "DriveTimeout (TimeoutError)" in tree.tree_text()
