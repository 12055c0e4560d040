"""tests/bytecode_warmup.py (xdist's controller makes the bytecode before the workers start) writes nothing where
Python writes nothing, and a tree it cannot write to still runs: its pytest_configure must not stop the suite."""

from __future__ import annotations

import pathlib

import pytest

from tests.bytecode_warmup import PACKAGES, warm


def tree(root: pathlib.Path) -> pathlib.Path:
    """A project tree of the warm-up's shape: each package with a module, a test module and a conftest."""
    for package in PACKAGES:
        (root / package).mkdir(parents=True)
        (root / package / "__init__.py").write_text("VALUE = 1\n")
    (root / "tests").mkdir()
    (root / "tests" / "test_sample.py").write_text("def test_one():\n    assert 1 + 1 == 2\n")
    (root / "tests" / "conftest.py").write_text("\n")
    return root


def test_it_writes_bytecode_where_none_is(tmp_path: pathlib.Path, pytestconfig: pytest.Config) -> None:
    root = tree(tmp_path)
    warm(pytestconfig, root)
    for package in PACKAGES:
        assert list((root / package / "__pycache__").glob("__init__.*.pyc"))
    if pytestconfig.getoption("assertmode") == "rewrite":  # the test modules' rewritten code, as pytest caches it
        assert list((root / "tests" / "__pycache__").glob("test_sample.*-pytest-*.pyc"))


def test_it_writes_none_under_pythondontwritebytecode(tmp_path: pathlib.Path, pytestconfig: pytest.Config,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    root = tree(tmp_path)
    monkeypatch.setattr("sys.dont_write_bytecode", True)  # PYTHONDONTWRITEBYTECODE=1 or python -B
    warm(pytestconfig, root)
    assert not list(root.rglob("__pycache__"))  # before: every package's and the tests' (453 files in a clone)


def test_a_tree_it_cannot_write_to_is_left_as_it_is_without_a_word(tmp_path: pathlib.Path, pytestconfig: pytest.Config,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    # a __pycache__ that is a file stands for a read-only tree (the suite runs as root here, which a mode bit does not
    # stop): before, the tests' mkdir raised out of pytest_configure (INTERNALERROR: the suite did not run at all with
    # -n on a read-only mount) and compileall printed two lines per module it could not write
    root = tree(tmp_path)
    for where in (*PACKAGES, "tests"):
        (root / where / "__pycache__").write_text("")
    warm(pytestconfig, root)
    out = capsys.readouterr()
    assert "Error" not in out.out + out.err
    assert all((root / where / "__pycache__").is_file() for where in (*PACKAGES, "tests"))
