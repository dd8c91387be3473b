"""The module map of docs/architecture.md as a contract: import-linter's layers contract in pyproject.toml
(a room imports only rooms below it; the base modules import none of each other; meshes/ knows only gmsh)
holds for the code, and an upward import added to a copy of the code breaks it; ruff's lint rules hold too."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from conftest import on_rank0

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(where: Path) -> subprocess.CompletedProcess:
    assert LINT.is_file(), f"{LINT} is missing: scripts/test.sh installs scripts/test-requirements.txt"
    env = {**os.environ, "PYTHONPATH": str(where)}  # this tree's app/ and meshes/, not the installed ones
    return subprocess.run([str(LINT), "--no-cache"], cwd=where, env=env, capture_output=True, text=True,
                          timeout=300)


def test_the_code_keeps_its_layers():
    done = on_rank0(_lint, ROOT)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert "2 kept, 0 broken" in done.stdout, done.stdout[-2000:]


def test_the_code_passes_its_lint():
    """ruff's rules of pyproject.toml (pyflakes, pycodestyle to 120 columns, import order, bugbear, pyupgrade) hold
    on app/ and meshes/ with no finding."""
    ruff = Path(sys.executable).with_name("ruff")
    assert ruff.is_file(), f"{ruff} is missing: scripts/test.sh installs scripts/test-requirements.txt"
    done = on_rank0(lambda: subprocess.run([str(ruff), "check", "--no-cache", "app", "meshes"], cwd=ROOT,
                                           capture_output=True, text=True, timeout=300))
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]


def _copy_with(tmp: Path, path: str, line: str) -> Path:
    for part in ("app", "meshes"):
        shutil.copytree(ROOT / part, tmp / part, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp)
    target = tmp / path
    target.write_text(target.read_text() + f"\n\n{line}\n")
    return tmp


def test_an_upward_import_breaks_the_contract(shared_tmp):
    """The physics importing the command line (model -> cli), and a gmsh builder importing app/."""
    done = on_rank0(lambda: _lint(_copy_with(shared_tmp / "up", "app/model/material.py",
                                             "from app import cli  # noqa: E402")))
    assert done.returncode == 1, done.stdout[-3000:]
    assert "app.model is not allowed to import app.cli" in done.stdout, done.stdout[-3000:]
    assert "app.model.material -> app.cli" in done.stdout, done.stdout[-3000:]
    assert "1 kept, 1 broken" in done.stdout, done.stdout[-2000:]

    done = on_rank0(lambda: _lint(_copy_with(shared_tmp / "meshes", "meshes/bilayer.py",
                                             "import app.schema  # noqa: E402")))
    assert done.returncode == 1, done.stdout[-3000:]
    assert "meshes.bilayer -> app.schema" in done.stdout, done.stdout[-3000:]


def test_reading_and_checking_a_config_does_not_load_dolfinx():
    """The config layer and the geometry kinds' keys, defaults and checks need no finite elements: reading and
    validating a config (what `hydrobuckle validate` and every command's pre-flight do) leaves dolfinx and PETSc
    unloaded (about a second of start-up each), so a bad config is refused at once. A module-level import of
    the compat layer or of fem_utils in a room config reads (geometry.base, the kinds, the criteria's
    registry) breaks this."""
    probe = ("import sys, app.config; app.config.validate(app.config.resolve({'geometry': {'kind': 'tube'}})); "
             "print(sorted(m for m in ('dolfinx', 'petsc4py') if m in sys.modules))")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = on_rank0(lambda: subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env=env, capture_output=True,
                                           text=True, timeout=120))
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "[]", done.stdout
