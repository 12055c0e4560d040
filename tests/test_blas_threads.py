"""The console script asks numpy's and scipy's BLAS libraries for one thread each, unless the
environment names a count (the run's thread names themselves: tests/test_run_crash.py)."""

from __future__ import annotations

import os

import pytest

from haptic_bus.app.blas_threads import BLAS_THREADS, one_blas_thread

COUNTS = {name for own, after in BLAS_THREADS.items() for name in (own, *after)}  # every variable a BLAS reads a count from


def _environment(monkeypatch: pytest.MonkeyPatch, **names: str) -> dict[str, str]:
    """This process's environment without a BLAS thread count but ``names``, as a copy ``os.environ`` is for the test."""
    environment = {name: value for name, value in os.environ.items() if name not in COUNTS} | names
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


def test_a_count_a_library_reads_after_its_own_variable_is_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    """OpenBLAS reads GOTO_NUM_THREADS, then OMP_NUM_THREADS, when OPENBLAS_NUM_THREADS names no count; MKL reads
    OMP_NUM_THREADS: a user's OMP_NUM_THREADS=2 is theirs for both, GOTO_NUM_THREADS=2 for OpenBLAS alone."""
    environment = _environment(monkeypatch, OMP_NUM_THREADS="2")
    one_blas_thread()
    assert not {"OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"} & environment.keys()
    environment = _environment(monkeypatch, GOTO_NUM_THREADS="2", OMP_NUM_THREADS="")
    one_blas_thread()
    assert "OPENBLAS_NUM_THREADS" not in environment and environment["MKL_NUM_THREADS"] == "1"
