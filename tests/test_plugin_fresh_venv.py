"""Done when: the plugin's README example passes from a fresh virtual environment.

``python -m venv --without-pip`` (no system site-packages, no packages at all), then ``pip
--python VENV install`` of this source tree and pytest by the suite's own pip (pip >= 22.3 installs
into another interpreter's environment: the venv gets only what the distribution asks for, and
skipping ``ensurepip`` saves 5 s of CPU and 13 s here), its dependencies resolved by pip from the
configured package index; then the README's
example, alone in a folder of its own (no conftest.py, no PYTHONPATH), run by that
environment's pytest.  The fixtures can only come from the installed distribution's
``pytest11`` entry point: pytest lists the plugin at the environment's site-packages (the run's
``--trace-config`` header), and with the plugin blocked (``-p no:haptic_bus.testing``) the same
file fails for want of them.

The source is copied first (the packages pyproject.toml names, pyproject.toml and the README),
so the build leaves nothing in the working tree.  About 40 s and 14 s of CPU here on a loaded
2-core machine: the install 10-13 s of CPU with pip 26 (the test extra asks pip >= 25: pip 23.2 took
15-19 s), of which unpacking the wheels is 7 s and pip's resolution against the index 4 s, the two
pytest runs 4 s.
Kept as it is: ``--system-site-packages`` would add the base interpreter's site-packages (here
hundreds of packages: not a fresh machine), ``--no-deps`` or the suite's own packages would no
longer prove that the distribution's declared dependencies suffice for the example.
"""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess
import sys
import tomllib

import pytest

from haptic_bus._version import __version__
from tests.plugin_readme import REPO, readme_plugin_example

pytestmark = pytest.mark.slow

# Bounds on a hang, measured at a load average of 3 to 5 on this 2-core machine:
VENV_WAIT = 60.0  # s of wall clock: python -m venv --without-pip (0.1 s measured)
INSTALL_WAIT = 900.0  # s of wall clock: pip install of the package and its dependencies (48-70 s measured)
PYTEST_WAIT = 600.0  # s of wall clock: the example's first run, imports compiled, its plots (35 s measured)


def _copy_source(destination: pathlib.Path) -> pathlib.Path:
    """The files a build of this distribution reads, copied to ``destination``."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    packages = {pattern.rstrip("*") for pattern in project["tool"]["setuptools"]["packages"]["find"]["include"]}
    for name in sorted(packages):
        shutil.copytree(REPO / name, destination / name, ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, destination / name)
    return destination


def _run(args: list[str], cwd: pathlib.Path, timeout: float) -> subprocess.CompletedProcess[str]:
    """``args`` in ``cwd`` with this environment less PYTHONPATH (nothing of this tree leaks in)."""
    env = {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def test_the_readme_example_passes_from_a_fresh_virtual_environment(tmp_path: pathlib.Path) -> None:
    venv = tmp_path / "venv"
    python = venv / "bin" / "python"
    made = _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path, VENV_WAIT)
    assert made.returncode == 0, made.stderr[-2000:]
    source = _copy_source(tmp_path / "source")
    installed = _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-compile", str(source), "pytest"],
                     tmp_path, INSTALL_WAIT)
    assert installed.returncode == 0, installed.stdout[-2000:] + installed.stderr[-2000:]

    project = tmp_path / "user-project"
    project.mkdir()
    (project / "test_readme_example.py").write_text(readme_plugin_example())
    # --trace-config: the header also says where each plugin was loaded from, as pytest -VV does (one process fewer)
    passed = _run([str(python), "-m", "pytest", "-p", "no:cacheprovider", "--trace-config", "test_readme_example.py"],
                  project, PYTEST_WAIT)
    assert passed.returncode == 0, passed.stdout[-4000:] + passed.stderr[-2000:]
    assert "1 passed" in passed.stdout and "plugins: haptic_bus-" in passed.stdout, passed.stdout[-2000:]
    site = venv / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
    assert f"haptic_bus-{__version__} at {site / 'haptic_bus' / 'testing' / '__init__.py'}" in passed.stdout, \
        passed.stdout[-4000:]

    blocked = _run([str(python), "-m", "pytest", "-p", "no:cacheprovider", "-p", "no:haptic_bus.testing",
                    "test_readme_example.py"], project, PYTEST_WAIT)
    assert blocked.returncode == 1 and "fixture 'haptic_sim' not found" in blocked.stdout, blocked.stdout[-2000:]
