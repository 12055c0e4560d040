"""The suite's bytecode, made once before pytest-xdist's workers start (tests/conftest.py calls :func:`warm`).

In a fresh tree each worker compiles the project's modules, and pytest rewrites the asserts of every test
module, as it collects: all of them at once, the same files.  Measured here (2 cores): a collection took
8.0-9.0 s of CPU without the caches and 3.2 s with them, so three workers spent about 16 s of CPU (8 s of
the suite's wall clock, 152 s in a fresh clone against 142 s in a used one) making the same files three
times.  The controller makes them once, before it starts the workers: the project's packages with
:mod:`compileall`, the test modules and conftest with pytest's own rewrite (its ``_rewrite_test`` and
``_write_pyc``, which its import hook calls: private, so where they are gone the workers write the caches
themselves, as before).  A tree already cached costs a look at each file.
"""

from __future__ import annotations

import compileall
import pathlib
import sys

import pytest

PACKAGES = ("haptic_bus", "drives", "sim_drive")


def warm(config: pytest.Config, root: pathlib.Path) -> None:
    """The bytecode of the project's :data:`PACKAGES` under ``root`` and of its tests' modules, where missing or stale;
    none where Python writes none (``PYTHONDONTWRITEBYTECODE``, ``-B``), and nothing said where it cannot write (a
    read-only tree: the workers read the sources, as pytest and Python do there)."""
    if sys.dont_write_bytecode:  # the user's choice: pytest and Python write no bytecode either
        return
    for package in PACKAGES:
        compileall.compile_dir(root / package, quiet=2)  # 2: no line per file it cannot write (an import says more)
    try:
        from _pytest.assertion import assertstate_key
        from _pytest.assertion.rewrite import PYC_TAIL, _read_pyc, _rewrite_test, _write_pyc, get_cache_dir
    except ImportError:  # another pytest: its workers rewrite as they collect
        return
    state = config.stash.get(assertstate_key, None)
    if state is None:  # assertion rewriting is off (--assert=plain)
        return
    tests = root / "tests"
    for path in sorted([*tests.glob("test_*.py"), tests / "conftest.py"]):
        pyc = get_cache_dir(path) / (path.name[:-3] + PYC_TAIL)
        if _read_pyc(path, pyc) is not None:
            continue
        try:
            pyc.parent.mkdir(parents=True, exist_ok=True)  # parents: under a PYTHONPYCACHEPREFIX too
        except OSError:  # a read-only tree: pytest's own hook then writes nothing either
            return
        source_hash, code = _rewrite_test(path, config)
        _write_pyc(state, code, source_hash, pyc)  # False (and nothing written) where it cannot
