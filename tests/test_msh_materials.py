"""A user .msh whose layers name neither "film" nor "substrate" (docs/reliability.md): the cell
groups of a mesh written by `hydrobuckle mesh` are renamed with the gmsh API and given materials of
other names. Reference: the same file with its original names and the built-in materials of the
same parameters (identical g_c and N_c); the run's log line, summary, plots and mode files name
the materials that exist."""

from __future__ import annotations

import logging

import pytest
from cases import TINY_BILAYER_TOML
from conftest import on_rank0, read_json

from app import cli, logging_setup

BASE = """
[geometry]
kind = "msh"
file = "{file}"
wrinkles = "along"
{layers}
boundaries = {{ top = "permeable", bottom = "roller_y", left = "roller_x", right = "roller_x" }}
[time]
end = {end}
dt_initial = 0.001
dt_max = 0.05
[stability]
error_estimate = false
{materials}
"""

BILAYER = TINY_BILAYER_TOML


def _rename(src, dst, names):
    import gmsh

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(str(src))
        groups = {}
        for dim, tag in gmsh.model.getPhysicalGroups(2):
            old = gmsh.model.getPhysicalName(dim, tag)
            gmsh.model.removePhysicalName(old)  # else the file keeps the old name
            gmsh.model.setPhysicalName(dim, tag, names[old])
            groups[names[old]] = tag
        facets = sorted(gmsh.model.getPhysicalName(d, t) for d, t in gmsh.model.getPhysicalGroups(1))
        gmsh.write(str(dst))
        return sorted(groups), facets
    finally:
        gmsh.finalize()


@pytest.fixture
def msh_files(shared_tmp):
    on_rank0((shared_tmp / "bilayer.toml").write_text, BILAYER)
    assert cli.main(["mesh", str(shared_tmp / "bilayer.toml"), "-o", str(shared_tmp / "std.msh")]) == 0
    cells, facets = on_rank0(_rename, shared_tmp / "std.msh", shared_tmp / "renamed.msh",
                             {"film": "skin", "substrate": "base"})
    assert cells == ["base", "skin"]
    assert {"top", "bottom", "left", "right"} <= set(facets)
    return shared_tmp / "std.msh", shared_tmp / "renamed.msh"


def _write(path, **kw):
    on_rank0(path.write_text, BASE.format(**kw))
    return str(path)


def test_layers_named_otherwise_run_like_the_built_in_names(msh_files, shared_tmp, comm, capsys):
    std, renamed = msh_files
    ref_cfg = _write(shared_tmp / "std.toml", file=std, end=1.0, materials="",
                     layers='layers = { film = "film", substrate = "substrate" }')
    cfg = _write(shared_tmp / "renamed.toml", file=renamed, end=1.0,
                 layers='layers = { skin = "stiff", base = "gel" }',
                 materials="[material.layers.stiff]\nmodulus_ratio = 8.0\n[material.layers.gel]\nmodulus_ratio = 1.0")
    assert cli.main(["run", ref_cfg, "-o", str(shared_tmp / "ref"), "-q"]) == 0
    capsys.readouterr()
    try:
        assert cli.main(["run", cfg, "-o", str(shared_tmp / "out")]) == 0  # with the log lines
    finally:
        logging_setup.setup(comm, logging.WARNING)
    stdout = capsys.readouterr().out
    ref, got = read_json(shared_tmp / "ref" / "summary.json"), read_json(shared_tmp / "out" / "summary.json")
    if comm.rank == 0:
        first = next(line for line in stdout.splitlines() if " mesh with " in line)
        assert "gel mu0 = " in first and "stiff mu0 = " in first and "film" not in first, first
    assert ref["status"] == got["status"] == "buckled"
    assert sorted(got["materials"]) == ["gel", "stiff"]
    for a, b in (("stiff", "film"), ("gel", "substrate")):
        assert got["materials"][a] == ref["materials"][b]
    assert got["critical"]["growth_mm"] == pytest.approx(ref["critical"]["growth_mm"], rel=1e-12)
    assert got["critical"]["wrinkle_count"] == ref["critical"]["wrinkle_count"]
    for name in ("history.png", "mode.png", "mode.xdmf", "mode_surface.csv", "fields.xdmf"):
        assert (shared_tmp / "out" / name).stat().st_size > 0, name


def test_all_cells_one_material_gel(msh_files, shared_tmp, comm):
    _, renamed = msh_files
    cfg = _write(shared_tmp / "gel.toml", file=renamed, end=0.05,
                 layers='layers = { skin = "gel", base = "gel" }',
                 materials="[material.layers.gel]\nmodulus_ratio = 1.0")
    assert cli.main(["run", cfg, "-o", str(shared_tmp / "gel"), "-q"]) == 0
    s = read_json(shared_tmp / "gel" / "summary.json")
    assert s["status"] == "stable"
    assert list(s["materials"]) == ["gel"]
    assert (shared_tmp / "gel" / "history.png").stat().st_size > 0
