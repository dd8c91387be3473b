"""A user's own .msh mesh with default settings (docs/geometries.md, "Your own geometry"): the docs' example run
exactly as written ends with summary.json and an error bar; a .msh mesh is refined by splitting every
cell (mesh.refinements), which keeps the file's geometry and groups; converge refines a .msh mesh.

Before the fix the example's run computed its onset and its time companion, then died in the mesh
companion (``mesh.element_size`` is None for a file): exit 1, a traceback, no summary.json."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import EXE, REPO, child_env, on_rank0, read_csv, read_json
from mpi4py import MPI

from app import cli, config
from app.workflows.run import simulate

GUIDE = REPO / "docs" / "geometries.md"  # the user's guide page with the example


def _block(marker: str, lang: str) -> str:
    """The fenced ``lang`` block after ``<!-- own-geometry:marker -->`` in docs/geometries.md."""
    text = GUIDE.read_text()
    i = text.index(f"<!-- own-geometry:{marker} -->")
    j = text.index(f"```{lang}\n", i) + len(f"```{lang}\n")
    return text[j:text.index("```", j)]


def _readme_example(workdir):
    """The example's commands, in a directory where ``configs/`` is the checkout's (as in the checkout)."""
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "configs").symlink_to(REPO / "configs")
    (workdir / "my.toml").write_text(_block("my.toml", "toml"))
    env = child_env()
    env["PATH"] = f"{Path(EXE).parent}{os.pathsep}{env['PATH']}"  # `source .venv/bin/activate`
    env["PYTHONPATH"] = str(REPO)  # this checkout's app (a scratch copy's too, scripts/mutation-check.sh)
    out = []
    for line in _block("commands", "bash").strip().splitlines():
        command = line.split("#")[0].strip()
        proc = subprocess.run(["bash", "-c", command], cwd=workdir, env=env, capture_output=True, text=True,
                              timeout=900)
        out.append((command, proc.returncode, proc.stdout + proc.stderr))
    return out


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the guide's commands are serial: the serial session runs them")
def test_readme_own_geometry_example_as_written(tmp_path, comm):
    """Each command exits 0 without a traceback; the run ends with the result line and summary.json
    holding g_c and both parts of its error bar, the mesh part from the file split once (4x its cells);
    its g_c equals the built-in bilayer's on the same mesh (the file is that mesh: reading it back
    changes nothing, to roundoff)."""
    results = _readme_example(tmp_path)
    for command, code, text in results:
        assert code == 0 and "Traceback" not in text, (command, text[-3000:])
    last = results[-1][2].strip().splitlines()[-1]
    assert re.search(r"hydrobuckle: result: g_c = [0-9.]+ um \+- [0-9.]+ um, N_c = ", last), last
    out = tmp_path / re.search(r"-o (\S+)", results[-1][0]).group(1)
    s = read_json(out / "summary.json")
    assert s["status"] == "buckled" and "after_run_error" not in s
    err = s["critical"]["discretization_error"]
    assert err["time_um"] > 0 and err["mesh_um"] > 0
    assert err["total_um"] == pytest.approx(err["time_um"] + err["mesh_um"], rel=1e-12)
    assert err["time_companion"] == "coarsened" and err["mesh_companion"] == "refined"
    assert err["time_companion_mesh"] == "the run's"  # no coarse mesh: the time companion on the run's
    assert read_json(out / "error-estimate" / "time" / "summary.json")["mesh"]["cells"] == s["mesh"]["cells"]
    fine = read_json(out / "error-estimate" / "mesh" / "summary.json")
    assert fine["config"]["mesh"]["refinements"] == 1
    assert fine["mesh"]["cells"] == 4 * s["mesh"]["cells"]
    # the mesh error from the refined companion: |g - g_fine| 2^p / (2^p - 1), p = 1.5
    d = abs(s["critical"]["growth_um"] - fine["critical"]["growth_um"])
    assert err["mesh_um"] == pytest.approx(d * 2 ** 1.5 / (2 ** 1.5 - 1), rel=1e-12)

    mesh_cmd = results[0][0]
    overrides = re.findall(r"--set (\S+)", mesh_cmd)
    built_in = config.load(REPO / "configs" / "bilayer.toml", overrides)  # the geometry and mesh of my.msh
    own = config.load(tmp_path / "my.toml")
    for table in ("material", "loading", "time", "solver", "stability"):  # everything else: my.toml's
        built_in[table] = own[table]
    built_in["stability"]["error_estimate"] = False
    built_in["output"].update(fields=False, plot=False)
    config.validate(built_in)
    ref = simulate(built_in, tmp_path / "built-in", comm, progress=False)
    assert ref["mesh"]["cells"] == s["mesh"]["cells"]
    assert s["critical"]["wrinkle_count"] == ref["critical"]["wrinkle_count"]
    assert s["critical"]["growth_um"] == pytest.approx(ref["critical"]["growth_um"], rel=1e-9)


def _write_msh(shared_tmp, name: str, cfg_path: str, *overrides) -> str:
    path = shared_tmp / name
    argv = ["mesh", cfg_path, "-o", str(path)]
    for o in overrides:
        argv += ["--set", o]
    assert cli.main(argv) == 0
    return str(path)


def _group_stats(path: str, refinements: int):
    """Rank 0: per physical group the element count, area (cells) or length (facets), and the largest
    distance of any node of the 'inner' group from the circle of the file's inner nodes' radius."""
    import gmsh

    from meshes import msh

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.merge(path)
        msh.refine(refinements)
        out = {}
        for dim, tag in gmsh.model.getPhysicalGroups():
            name = gmsh.model.getPhysicalName(dim, tag)
            count, size, nodes = 0, 0.0, []
            for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
                types, _, enodes = gmsh.model.mesh.getElements(dim, ent)
                for et, en in zip(types, enodes):
                    k = 4 if dim == 2 else 2
                    en = np.asarray(en, dtype=np.int64).reshape(-1, k)
                    count += len(en)
                    xyz = np.array([gmsh.model.mesh.getNode(int(n))[0][:2] for n in en.ravel()]).reshape(-1, k, 2)
                    if dim == 2:  # shoelace area of each quad
                        x, y = xyz[..., 0], xyz[..., 1]
                        size += 0.5 * float(np.abs(np.sum(x * np.roll(y, -1, 1) - np.roll(x, -1, 1) * y, 1)).sum())
                    else:
                        size += float(np.linalg.norm(xyz[:, 1] - xyz[:, 0], axis=1).sum())
                        nodes.append(xyz.reshape(-1, 2))
            out[(dim, name)] = (count, size, np.concatenate(nodes) if nodes else None)
        return out
    finally:
        gmsh.finalize()


def test_refinement_splits_every_cell_and_keeps_the_file_geometry(shared_tmp):
    """mesh.refinements = k: 4^k cells and 2^k segments per group; every group's area and boundary
    length unchanged (the refined mesh covers the file's polygon exactly: new nodes on its edges)."""
    bil = _write_msh(shared_tmp, "bil.msh", str(REPO / "configs" / "bilayer.toml"), "mesh.element_size=0.05",
                     "mesh.film_layers=1")
    tube = _write_msh(shared_tmp, "tube.msh", str(REPO / "configs" / "tube.toml"), "mesh.element_size=0.1",
                      "mesh.film_layers=1")
    for path in (bil, tube):
        base, twice = on_rank0(_group_stats, path, 0), on_rank0(_group_stats, path, 2)
        assert base.keys() == twice.keys()
        for key, (count, size, _) in base.items():
            assert twice[key][0] == count * (16 if key[0] == 2 else 4), key
            assert twice[key][1] == pytest.approx(size, rel=1e-12), key
    base, twice = on_rank0(_group_stats, tube, 0), on_rank0(_group_stats, tube, 2)
    # the passage: every refined node lies on a segment of the file's polygon (not on the circle)
    poly = base[(1, "inner")][2].reshape(-1, 2, 2)
    pts = twice[(1, "inner")][2]
    a, b = poly[:, 0][None], poly[:, 1][None]
    t = np.clip(np.einsum("pij,pij->pi", pts[:, None] - a, b - a) / np.einsum("pij,pij->pi", b - a, b - a), 0, 1)
    dist = np.linalg.norm(pts[:, None] - (a + t[..., None] * (b - a)), axis=2).min(axis=1)
    assert dist.max() < 1e-12


def test_refinements_key_is_for_the_msh_kinds_only(comm):
    with pytest.raises(config.ConfigError, match=r"mesh.refinements.*'msh' and 'msh-3d' only; allowed for 'bilayer': 0"):
        config.resolve({"mesh": {"refinements": 1}})
    with pytest.raises(config.ConfigError, match=r"mesh.refinements.*allowed: in \[0, 4\]"):
        config.resolve({"geometry": {"kind": "msh", "file": "x.msh", "layers": {"film": "film"},
                                     "boundaries": {"top": "permeable"}}, "mesh": {"refinements": 5}})


def _small_msh_config(shared_tmp) -> str:
    path = _write_msh(shared_tmp, "strip.msh", str(REPO / "configs" / "bilayer.toml"), "geometry.length=0.3",
                      "geometry.substrate_thickness=0.15", "mesh.element_size=0.01", "mesh.film_layers=2",
                      "mesh.substrate_grading=1.25")
    text = (f'[geometry]\nkind = "msh"\nfile = "{path}"\nlayers = {{ film = "film", substrate = "substrate" }}\n'
            'boundaries = { top = "permeable", bottom = "roller_y", left = "roller_x", right = "roller_x" }\n'
            '[time]\nend = 1.0\ndt_max = 0.05\n[output]\nfields = false\nplot = false\n')
    cfg = shared_tmp / "strip.toml"
    if MPI.COMM_WORLD.rank == 0:
        cfg.write_text(text)
    MPI.COMM_WORLD.barrier()
    return str(cfg)


def test_converge_refines_a_msh_mesh(shared_tmp, comm, capsys):
    """`converge` of a .msh config (both studies, 2 levels): the mesh levels are the file split 0 and 1
    times (4x the cells), the report has a base estimate; `--coarsen` of an unrefined file is refused
    with one line naming mesh.refinements, exit 2, nothing created."""
    cfg = _small_msh_config(shared_tmp)
    out = shared_tmp / "conv"
    assert cli.main(["converge", cfg, "--levels", "2", "-o", str(out), "-q"]) == 0
    rep = read_json(out / "convergence.json")
    assert rep["base"]["error_estimate_um"] > 0
    assert rep["studies"]["mesh"]["values"][0] == rep["base"]["g_c_um"]
    rows = {(r["study"], int(r["level"])): r for r in read_csv(out / "convergence.csv")}
    assert float(rows[("mesh", 1)]["parameter"]) == 0.5
    assert read_json(out / "mesh1" / "summary.json")["mesh"]["cells"] == \
        4 * read_json(out / "base" / "summary.json")["mesh"]["cells"]
    capsys.readouterr()
    refused = shared_tmp / "conv-coarsen"
    assert cli.main(["converge", cfg, "--levels", "2", "--coarsen", "-o", str(refused)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    if comm.rank == 0:
        assert len(err) == 1 and "'mesh.refinements'" in err[0] and "cannot be coarsened" in err[0], err
    assert not refused.exists()


def test_msh_run_with_default_settings_reports_an_error_bar(shared_tmp, comm):
    """The same path as the guide's example on a small file, in-process (serially and on 2 ranks): a .msh
    run with the default stability.error_estimate ends buckled with both parts of its error bar, the mesh
    part from the file split once (4x the cells), the time part from a companion 2x coarser in its steps."""
    from app.workflows.pipeline import run_case

    cfg = config.load(_small_msh_config(shared_tmp))
    assert cfg["stability"]["error_estimate"] and cfg["mesh"]["refinements"] == 0
    out = shared_tmp / "msh-run"
    s = run_case(cfg, out, comm, progress=False)
    assert s["status"] == "buckled" and "after_run_error" not in s
    err = s["critical"]["discretization_error"]
    assert err["mesh_companion"] == "refined" and err["mesh_um"] > 0 and err["time_um"] > 0
    fine = read_json(out / "error-estimate" / "mesh" / "summary.json")
    assert fine["mesh"]["cells"] == 4 * s["mesh"]["cells"]
    assert read_json(out / "summary.json")["critical"]["discretization_error"] == err
