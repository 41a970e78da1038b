"""Install paths: pip over Debian's packages, one line when a part of the PETSc stack is missing."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

from ddsolve import __version__, environment

pytestmark = pytest.mark.mpi

DEBIAN_PYTHON = Path("/usr/bin/python3")


def clean_environment(**extra: str) -> dict[str, str]:
    """os.environ without PETSC_DIR (ddsolve may have set it), this checkout on PYTHONPATH, or pip
    settings (no configured index or find-links: only what is installed can satisfy pip)."""
    removed = {"PETSC_DIR", "PYTHONPATH", "VIRTUAL_ENV"}
    env = {k: v for k, v in os.environ.items() if k not in removed and not k.startswith("PIP_")}
    return {**env, "PIP_CONFIG_FILE": os.devnull, "PYTHONNOUSERSITE": "1", **extra}


def run(*command: str | Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    completed = subprocess.run([str(c) for c in command], capture_output=True, text=True, env=env,
                               stdin=subprocess.DEVNULL, timeout=300)
    assert completed.returncode == 0, f"{command} failed:\n{completed.stdout}\n{completed.stderr}"
    return completed


def installed(python: Path, env: dict[str, str]) -> dict[str, str]:
    listing = run(python, "-m", "pip", "list", "--format=json", "--disable-pip-version-check", env=env)
    return {package["name"]: package["version"] for package in json.loads(listing.stdout)}


def test_pip_install_over_debian_packages_adds_only_ddsolve(tmp_path):
    """pip, offline, in a venv that sees Debian's packages: nothing is downloaded, built or shadowed,
    and the installed ``ddsolve`` finds Debian's PETSc with PETSC_DIR unset."""
    if not DEBIAN_PYTHON.exists():
        pytest.skip(f"no {DEBIAN_PYTHON}")
    if subprocess.run([DEBIAN_PYTHON, "-c", "import ensurepip, venv"], capture_output=True).returncode:
        pytest.skip(f"{DEBIAN_PYTHON} cannot create virtual environments (python3-venv)")
    petsc_dirs = environment.debian_petsc_dirs()
    if not petsc_dirs:
        pytest.skip(f"no Debian petsc4py under {environment.DEBIAN_PETSC_ROOT}")
    source = tmp_path / "source"  # a copy: pip builds in the source tree
    shutil.copytree(ROOT / "ddsolve", source / "ddsolve", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source)
    env = clean_environment()
    venv = tmp_path / "venv"
    run(DEBIAN_PYTHON, "-m", "venv", "--system-site-packages", venv, env=env)
    python = venv / "bin" / "python"
    before = installed(python, env)
    run(python, "-m", "pip", "install", "--quiet", "--no-index", "--no-build-isolation",
        "--disable-pip-version-check", source, env=env)
    assert installed(python, env) == {**before, "ddsolve": __version__}
    version = run(venv / "bin" / "ddsolve", "version", env=env).stdout
    petsc_version = re.search(r"petsc(\d+\.\d+)", petsc_dirs[0].parent.name).group(1)
    assert f"PETSc {petsc_version}." in version, version


def blocked(module: str, folder: Path) -> dict[str, str]:
    """An environment in which ``import module`` fails as if it were not installed."""
    package = folder / module
    package.mkdir()
    message = f"No module named {module!r}"
    (package / "__init__.py").write_text(f"raise ModuleNotFoundError({message!r}, name={module!r})\n")
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), str(ROOT)]), "MPLBACKEND": "Agg"}


@pytest.mark.parametrize("module, command", [
    ("petsc4py", ["version"]),
    ("mpi4py", ["version"]),
    ("h5py", ["compare", "a.h5", "b.h5"]),
    ("gmsh", ["mesh", "partial-closure"]),
    ("petsc4py", ["solve", "-n", "4", "partial-closure"]),
])
def test_missing_module_is_one_line(tmp_path, module, command):
    completed = subprocess.run([sys.executable, "-m", "ddsolve", *command], capture_output=True, text=True,
                               env=blocked(module, tmp_path), cwd=tmp_path, stdin=subprocess.DEVNULL, timeout=120)
    assert completed.returncode == 1
    assert completed.stderr.count("\n") == 1 and "Traceback" not in completed.stderr, completed.stderr
    assert completed.stderr.startswith(f"ddsolve: error: {module} not found by {sys.executable}")
    assert environment.PACKAGES[module][0] in completed.stderr
    if module == "petsc4py":
        assert "PETSC_DIR" in completed.stderr
