"""The README as a new user meets it: short, and its command-line and Python examples run exactly as
written (from a directory where ``configs/`` and ``.venv`` are the checkout's), the Python example
printing the same g_c as ``hydrobuckle run`` on the same config.

The README's other blocks: the demo (``scripts/demo.sh``) runs in tests/test_console.py; the test and
docs commands are the suite and CI's docs build themselves."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from conftest import EXE, REPO, child_env, read_json
from mpi4py import MPI

README = REPO / "README.md"
serial_only = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the README's commands are serial: the serial "
                                 "session runs them")


def block(marker: str, lang: str, path: Path = README) -> str:
    """The fenced ``lang`` block right after ``<!-- marker -->``."""
    text = path.read_text()
    i = text.index(f"<!-- {marker} -->")
    j = text.index(f"```{lang}\n", i)
    assert text[i:j].count("\n") <= 1, f"the block after <!-- {marker} --> must follow it directly"
    j += len(f"```{lang}\n")
    return text[j:text.index("```", j)]


def _workdir(tmp_path: Path) -> tuple[Path, dict]:
    """A directory laid out as the checkout is for a user: ``configs/`` and ``.venv`` (the venv running the
    tests); the environment of a fresh shell there."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / "configs").symlink_to(REPO / "configs")
    (tmp_path / ".venv").symlink_to(Path(EXE).parent.parent)
    env = child_env()
    env["PYTHONPATH"] = str(REPO)  # this checkout's app (a scratch copy's too, scripts/mutation-check.sh)
    return tmp_path, env


def _bash(script: str, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-e", "-c", script], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)


def test_readme_fits_on_a_few_screens_and_links_to_existing_pages():
    """At most 200 lines; every relative link points to a file of the checkout (the docs' own pages, the
    figure); the README's Python example and the docs' API page use names the API exports."""
    import app

    text = README.read_text()
    assert len(text.splitlines()) <= 200
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    assert links, "the README links into the docs"
    for link in links:
        if "://" not in link:
            assert (REPO / link).exists(), link
    used = set(re.findall(r"\bhb\.(\w+)", text))
    assert used and used <= set(app.__all__), used - set(app.__all__)


@serial_only
@pytest.mark.slow
def test_readme_more_commands_run_as_written(tmp_path):
    """Each line exits 0 without a traceback; ``reduced`` writes its answer, ``study --list`` names every
    study the code has, ``validate`` prints a loadable config with its mesh estimate."""
    from app.workflows.studies import STUDIES

    cwd, env = _workdir(tmp_path)
    lines = [ln.split("#")[0].strip() for ln in block("readme:more", "bash").splitlines()]
    lines = [ln for ln in lines if ln]
    outputs = {}
    for line in lines:
        proc = _bash(f"source .venv/bin/activate\n{line}", cwd, env)
        assert proc.returncode == 0 and "Traceback" not in proc.stderr, (line, proc.stdout[-2000:], proc.stderr[-2000:])
        outputs.setdefault(line.split()[1], "")
        outputs[line.split()[1]] += proc.stdout
    reduced_dir = cwd / re.search(r"-o (\S+)", next(ln for ln in lines if " reduced " in ln)).group(1)
    s = read_json(reduced_dir / "summary.json")
    assert s["solver"] == "reduced-1d" and s["reduced"]["kind"] == "wrinkles"
    for name in STUDIES:
        assert name in outputs["study"]
    assert outputs["validate"].startswith("# mesh estimate:")


@serial_only
def test_readme_python_example_prints_the_g_c_of_the_cli_example(tmp_path):
    """The CLI block and the Python block, run as written: both exit 0; the Python example prints the
    g_c, error bar and N_c of the CLI's result line (same digits), and the two summaries agree to
    roundoff (the same serial computation: 1e-12); the Python example's 1D counterpart is the CLI's."""
    cwd, env = _workdir(tmp_path)
    cli = _bash(block("readme:cli", "bash"), cwd, env)
    assert cli.returncode == 0 and "Traceback" not in cli.stderr, cli.stderr[-3000:]
    line = re.search(r"hydrobuckle: result: g_c = ([0-9.]+) um \+- ([0-9.]+) um, N_c = (\S+?)\s",
                     cli.stdout + cli.stderr)
    assert line, (cli.stdout + cli.stderr)[-3000:]

    (cwd / "example.py").write_text(block("readme:python", "python"))
    py = subprocess.run([str(Path(EXE).parent / "python"), "example.py"], cwd=cwd, env=env, capture_output=True,
                        text=True, timeout=900)
    assert py.returncode == 0 and "Traceback" not in py.stderr, py.stderr[-3000:]
    printed = re.search(r"g_c = ([0-9.]+) um \+- ([0-9.]+) um, N_c = (\S+)", py.stdout)
    assert printed, py.stdout
    assert printed.groups() == line.groups(), (printed.group(0), line.group(0))

    out_cli = cwd / re.search(r"-o (\S+)", block("readme:cli", "bash")).group(1)
    out_api = cwd / re.search(r'hb\.run\(cfg, "([^"]+)"\)', block("readme:python", "python")).group(1)
    a, b = read_json(out_cli / "summary.json"), read_json(out_api / "summary.json")
    assert a["config"] == b["config"]
    assert b["critical"]["growth_um"] == pytest.approx(a["critical"]["growth_um"], rel=1e-12)
    assert b["critical"]["discretization_error"]["total_um"] == pytest.approx(
        a["critical"]["discretization_error"]["total_um"], rel=1e-12)
    assert b["critical"]["wrinkle_count"] == a["critical"]["wrinkle_count"]
    assert b["reduced"]["growth_um"] == pytest.approx(a["reduced"]["growth_um"], rel=1e-12)
    assert f"{a['reduced']['growth_um']:.4f}" in py.stdout  # the printed 1D counterpart


def test_block_reader_finds_each_marked_block():
    """The marked blocks exist and hold what the tests above run (a renamed marker fails here first)."""
    assert "hydrobuckle run" in block("readme:cli", "bash")
    assert "hb.run(" in block("readme:python", "python")
    assert "hydrobuckle reduced" in block("readme:more", "bash")
