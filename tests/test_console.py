"""The README's commands as a user types them: the installed console script, through scripts/demo.sh
under ``mpirun -n 2``, and an install into a fresh venv that must produce the console script.

These tests start their own processes (rank 0 launches them also when pytest itself runs under
``mpirun -n 2``), so they prove what the in-process tests cannot: that ``.venv/bin/hydrobuckle``
exists and works from any directory."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import dolfinx
import pytest
from conftest import EXE, REPO, child_env, launcher_quiet, on_rank0, ours
from mpi4py import MPI

# The demo's config (configs/bilayer.toml) shrunk to a 0.3 mm wide strip: seconds, still buckles.
SMALL = ["--set", "geometry.length=0.3", "--set", "geometry.substrate_thickness=0.15",
         "--set", "mesh.element_size=0.01", "--set", "mesh.film_layers=2", "--set", "mesh.substrate_grading=1.25",
         "--set", "stability.error_estimate=false", "--set", "time.dt_max=0.05"]


# scripts/install.sh and demo.sh are for the Debian packages and the checkout's .venv; with your own
# FEniCSx (docs/install.md, "Your own FEniCSx") the suite runs from your environment and skips their tests
DEBIAN_INSTALL = Path(sys.prefix).resolve() == (REPO / ".venv").resolve()
debian_scripts = pytest.mark.skipif(not DEBIAN_INSTALL, reason="scripts/install.sh and demo.sh: the checkout's "
                                    ".venv over the Debian packages, not this environment")


def _run(cmd, cwd, timeout=600):
    return subprocess.run(cmd, cwd=cwd, env=child_env(), capture_output=True, text=True, timeout=timeout)


@debian_scripts
def test_demo_script_runs_console_script_on_two_ranks(shared_tmp, comm):
    """`bash scripts/demo.sh` (install check + `mpirun -n 2 .venv/bin/hydrobuckle run`) from another
    directory; its g_c equals the in-process serial run of the same resolved config (1 vs 2 ranks)."""
    out = shared_tmp / "demo"
    proc = on_rank0(_run, ["bash", str(REPO / "scripts" / "demo.sh"), "-o", str(out), "-q", *SMALL], cwd="/")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ranks"] == 2
    assert summary["status"] == "buckled"
    for name in ("history.csv", "config.toml", "fields.xdmf", "fields.h5", "history.png", "mode.xdmf", "mode.png"):
        assert (out / name).stat().st_size > 0, name

    from app import config
    from app.workflows.run import simulate

    cfg = config.load(out / "config.toml")
    assert cfg == config.load(REPO / "configs" / "bilayer.toml", [s for s in SMALL if s != "--set"])
    cfg["output"].update(fields=False, plot=False)
    ref = simulate(cfg, shared_tmp / "in-process", comm, progress=False)
    assert ref["status"] == "buckled"
    assert summary["critical"]["wrinkle_count"] == ref["critical"]["wrinkle_count"]
    assert summary["critical"]["growth_mm"] == pytest.approx(ref["critical"]["growth_mm"], rel=1e-6)


def test_console_script_exit_codes_from_any_directory(shared_tmp):
    """Bad input: exit 2, one line naming the key, no result directory; `version` works; all through
    the console script the install made, started from / (no checkout on the import path)."""
    bad, out = shared_tmp / "bad.toml", shared_tmp / "r"
    if MPI.COMM_WORLD.rank == 0:
        bad.write_text("[geometry]\nsubstrate_thickness = -1\n")
    MPI.COMM_WORLD.barrier()
    exe = EXE
    # without launcher_quiet() (Open MPI 4) mpirun adds its own banner about a rank's non-zero exit;
    # Open MPI 5 always does, and ours() leaves it out
    proc = on_rank0(_run, ["mpirun", *launcher_quiet(), "-n", "2", exe, "run", str(bad), "-o", str(out)], cwd="/")
    assert proc.returncode == 2
    # both ranks' stderr: only rank 0 speaks, and Open MPI 5's launcher adds no PMIx line (the ranks finalize MPI
    # before rank 0's exit 2: app.interrupt.leave, docs/platforms.md)
    lines = [ln for ln in ours(proc.stderr) if ln.strip()]
    assert len(lines) == 1 and "'geometry.substrate_thickness'" in lines[0] and "> 0" in lines[0], proc.stderr
    assert not out.exists()
    ver = on_rank0(_run, [exe, "version"], cwd="/")
    assert ver.returncode == 0 and f"dolfinx {dolfinx.__version__}" in ver.stdout


@debian_scripts
def test_install_into_fresh_venv_creates_console_script(shared_tmp):
    """scripts/install.sh, started from the checkout's root (where `import app` works without any
    install), must still install hydrobuckle into a fresh venv and create its console script; a
    second run only checks. Rank 0 installs (in a 2-rank session too, so scripts/mutation-check.sh
    --ranks 2 sees the install mutations)."""
    on_rank0(_install_twice, shared_tmp / "venv")


def _install_twice(venv):
    env = {**child_env(), "HYDROBUCKLE_VENV": str(venv), "HYDROBUCKLE_NO_WARMUP": "1"}
    first = subprocess.run(["bash", "scripts/install.sh"], cwd=REPO, env=env, capture_output=True, text=True,
                           timeout=600)
    assert first.returncode == 0, first.stdout + first.stderr
    assert "installing hydrobuckle" in first.stdout
    assert (venv / "bin" / "hydrobuckle").is_file()
    ver = subprocess.run([str(venv / "bin" / "hydrobuckle"), "version"], cwd="/", env=env, capture_output=True,
                         text=True, timeout=120)
    assert ver.returncode == 0 and ver.stdout.startswith("hydrobuckle ")
    again = subprocess.run(["bash", "scripts/install.sh"], cwd=REPO, env=env, capture_output=True, text=True,
                           timeout=600)
    assert again.returncode == 0 and "installing" not in again.stdout




def test_pip_install_into_an_environment_that_has_dolfinx(shared_tmp):
    """A user's own FEniCSx (docs/install.md, "Your own FEniCSx"): `pip install -e .` into an environment that sees
    dolfinx, no apt and no scripts: it fetches nothing (hydrobuckle declares no pip dependencies, so pip
    cannot replace the user's stack), and the console script it makes reports the dolfinx of that
    environment and runs a command from any directory."""
    on_rank0(_pip_install, shared_tmp / "own-env")


def _pip_install(venv):
    env = {**child_env(), "PIP_NO_INDEX": "1"}  # nothing may come from an index
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True, timeout=300)
    pip = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--no-build-isolation", "-e",
                          str(REPO)], cwd="/", env=env, capture_output=True, text=True, timeout=600)
    assert pip.returncode == 0, pip.stdout[-2000:] + pip.stderr[-2000:]
    ver = subprocess.run([str(venv / "bin" / "hydrobuckle"), "version"], cwd="/", env=env, capture_output=True,
                         text=True, timeout=120)
    assert ver.returncode == 0 and f"dolfinx {dolfinx.__version__}" in ver.stdout, ver.stdout + ver.stderr
    val = subprocess.run([str(venv / "bin" / "hydrobuckle"), "validate", str(REPO / "configs" / "bilayer.toml")],
                         cwd="/", env=env, capture_output=True, text=True, timeout=300)
    assert val.returncode == 0, val.stdout[-2000:] + val.stderr[-2000:]
