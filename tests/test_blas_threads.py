"""The console script asks numpy's and scipy's BLAS libraries for one thread each, unless the
environment names a count (the run's thread names themselves: tests/test_run_crash.py)."""

from __future__ import annotations

import os

import pytest

from haptic_bus.app.blas_threads import BLAS_THREADS, one_blas_thread


def _environment(monkeypatch: pytest.MonkeyPatch, **names: str) -> dict[str, str]:
    """This process's environment without a BLAS thread count but ``names``, as a copy ``os.environ`` is for the test."""
    environment = {name: value for name, value in os.environ.items() if name not in BLAS_THREADS} | names
    monkeypatch.setattr(os, "environ", environment)
    return environment


def test_one_thread_is_asked_where_the_environment_names_none(monkeypatch: pytest.MonkeyPatch) -> None:
    environment = _environment(monkeypatch)
    one_blas_thread()
    assert {name: environment[name] for name in BLAS_THREADS} == dict.fromkeys(BLAS_THREADS, "1")


def test_a_count_the_user_named_is_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    environment = _environment(monkeypatch, OPENBLAS_NUM_THREADS="3")
    one_blas_thread()
    assert environment["OPENBLAS_NUM_THREADS"] == "3" and environment["MKL_NUM_THREADS"] == "1"


@pytest.mark.parametrize("value", ["", " ", "0", "-1", "auto"])
def test_a_value_that_names_no_count_is_replaced(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    """OpenBLAS reads these as no count and starts its whole pool (module docstring): ``OPENBLAS_NUM_THREADS=``
    left a run with an unnamed thread."""
    environment = _environment(monkeypatch, OPENBLAS_NUM_THREADS=value, MKL_NUM_THREADS=value)
    one_blas_thread()
    assert {name: environment[name] for name in BLAS_THREADS} == dict.fromkeys(BLAS_THREADS, "1")


@pytest.mark.parametrize("value", ["2", " 2", "+2", "02"])
def test_a_count_as_openblas_reads_it_is_kept(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    environment = _environment(monkeypatch, OPENBLAS_NUM_THREADS=value)
    one_blas_thread()
    assert environment["OPENBLAS_NUM_THREADS"] == value
