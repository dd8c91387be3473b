"""A user's own hexahedral .msh file (``geometry.kind = "msh-3d"``, docs/three-d.md, "Your own 3D mesh").

- The built-in plate and 3D tube written by ``hydrobuckle mesh`` and read back as a user's file with the same
  groups mapped to the same roles are the same problem: the run must agree with the built-in kind's to the
  solvers' roundoff (g_c and every step), the plate's top read as a plane and the passage as a cylinder.
- ``mesh.refinements`` splits every hexahedron into 8 and keeps the groups (the refined run is a different mesh
  of the same body: its g_c moves by less than the coarse run's distance to the 1D answer, not compared here).
- Malformed hexahedral files exit 2 with one line naming the cell, group or key, and create no result
  directory: tetrahedra, a left-handed cell among right-handed ones, a cell turned inside out, a hanging node,
  unjoined blocks, a 2D file given as 3D and the reverse, a permeable surface that is not a tensor grid, or
  neither flat nor a cylinder about z, or a cylinder that does not go all the way around (a quarter tube)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import read_csv
from mpi4py import MPI
from test_msh_malformed import HEX, QUAD, Writer, bilayer
from test_msh_malformed import _run_exits_2 as run_exits_2

from app import cli, config
from app.workflows.run import simulate

TET = 4
QUIET = {"stability": {"error_estimate": False}, "output": {"fields": False, "plot": False},
         "reduced": {"beside_2d": False}, "time": {"end": 1.5}}
PLATE = {"kind": "plate", "length": 0.05, "width": 0.025, "substrate_thickness": 0.05, "film_thickness": 0.01}
PLATE_MESH = {"element_size": 0.00625, "film_layers": 2, "substrate_grading": 1.25}
PLATE_ROLES = {"left": "roller_x", "right": "roller_x", "front": "roller_z", "back": "roller_z",
               "bottom": "roller_y", "top": "permeable"}
TUBE = {"kind": "tube-3d", "outer_radius": 0.2, "substrate_thickness": 0.05, "film_thickness": 0.01, "length": 0.02}
TUBE_ROLES = {"inner": "permeable", "outer": "fixed", "front": "roller_z", "back": "roller_z"}


def _export(tmp, name: str, geometry: dict, mesh: dict | None = None):
    cfg = config.resolve({"geometry": geometry, "mesh": mesh or {}}, [])
    path = tmp / f"{name}.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(config.dumps(cfg))
    MPI.COMM_WORLD.barrier()
    out = tmp / f"{name}.msh"
    assert cli.main(["mesh", str(path), "-o", str(out)]) == 0
    return cfg, out


def _user(path, roles: dict, **geometry) -> dict:
    return config.resolve({**QUIET, "geometry": {"kind": "msh-3d", "file": str(path),
                                                 "layers": {"film": "film", "substrate": "substrate"},
                                                 "boundaries": roles, **geometry}}, [])


def _same_run(a: dict, b: dict, dir_a, dir_b) -> None:
    assert a["status"] == b["status"] == "buckled" and a["steps"] == b["steps"]
    assert a["mesh"]["cells"] == b["mesh"]["cells"]
    ca, cb = a["critical"], b["critical"]
    assert abs(cb["growth_mm"] - ca["growth_mm"]) <= 1e-8 * ca["growth_mm"]
    assert [m["wave_vector"] for m in ca["modes"]] == [m["wave_vector"] for m in cb["modes"]]
    for ra, rb in zip(read_csv(dir_a / "history.csv"), read_csv(dir_b / "history.csv"), strict=True):
        for key in ("time", "growth_mm", "fluid_volume", "energy"):
            assert abs(float(rb[key]) - float(ra[key])) <= 1e-8 * max(abs(float(ra[key])), 1e-12), key


def test_the_plate_read_back_from_its_msh_file_is_the_plate(shared_tmp, comm):
    cfg, path = _export(shared_tmp, "plate", PLATE, PLATE_MESH)
    built = simulate(config.resolve({**QUIET, "geometry": PLATE, "mesh": PLATE_MESH}, []), shared_tmp / "built",
                     comm, progress=False)
    user = simulate(_user(path, PLATE_ROLES), shared_tmp / "user", comm, progress=False)
    _same_run(built, user, shared_tmp / "built", shared_tmp / "user")
    assert user["critical"]["modes"][0]["wave_vector"] == [1, 0]


@pytest.mark.slow
def test_the_3d_tube_read_back_from_its_msh_file_is_the_3d_tube(shared_tmp, comm):
    cfg, path = _export(shared_tmp, "tube", TUBE)
    built = simulate(config.resolve({**QUIET, "geometry": TUBE}, []), shared_tmp / "built-tube", comm, progress=False)
    user = simulate(_user(path, TUBE_ROLES), shared_tmp / "user-tube", comm, progress=False)
    _same_run(built, user, shared_tmp / "built-tube", shared_tmp / "user-tube")
    assert user["critical"]["wrinkle_count"] == built["critical"]["wrinkle_count"] > 2


def test_a_refined_hexahedral_file_has_8_times_the_cells_and_the_same_groups(shared_tmp, comm):
    from app import geometry

    _, path = _export(shared_tmp, "plate-r", PLATE, PLATE_MESH)
    coarse = geometry.build(config.geometry_input(_user(path, PLATE_ROLES)), comm)
    fine_cfg = config.resolve({**_user(path, PLATE_ROLES), "mesh": {"refinements": 1}}, [])
    fine = geometry.build(config.geometry_input(fine_cfg), comm)
    def owned(g, name):  # a rank's cells of a group include its ghosts
        return int((g.tm.cells(name) < g.tm.mesh.topology.index_map(3).size_local).sum())

    cells = [comm.allreduce(owned(g, name), op=MPI.SUM) for g in (coarse, fine) for name in ("film", "substrate")]
    assert cells[2:] == [8 * c for c in cells[:2]]
    assert fine.tm.facet_names == coarse.tm.facet_names and fine.wrinkles == coarse.wrinkles == "plane"


class Hexes(Writer):
    def block(self, name, lo, hi, n, shared=True, left_handed=(), etype=HEX, moved=None):
        """n[0] x n[1] x n[2] hexahedra on the box lo..hi (right-handed; those in ``left_handed`` with their
        top and bottom swapped), or 5 tetrahedra a box (etype TET); ``moved``: {(i, j, k): (x, y, z)}."""
        own: dict = {}
        moved = moved or {}

        def node(i, j, k):
            if (i, j, k) not in own:
                p = moved.get((i, j, k)) or [lo[a] + (hi[a] - lo[a]) * (i, j, k)[a] / n[a] for a in range(3)]
                own[(i, j, k)] = self.node(*p, shared=shared)
            return own[(i, j, k)]

        cells = []
        for k in range(n[2]):
            for j in range(n[1]):
                for i in range(n[0]):
                    bottom = [node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k)]
                    top = [node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1), node(i, j + 1, k + 1)]
                    if etype == TET:
                        a, b, c, d = bottom
                        e, f, g, h = top
                        cells += [[a, b, d, e], [b, c, d, g], [b, e, f, g], [d, e, g, h], [b, d, e, g]]
                    else:
                        cells.append(top + bottom if len(cells) in left_handed else bottom + top)
        self.cells[name] = (3, etype, cells)
        return node

    def face_group(self, name, node, ij_range, k):
        (i0, i1), (j0, j1) = ij_range
        self.cells[name] = (2, QUAD, [[node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k)]
                                      for j in range(j0, j1) for i in range(i0, i1)])


def _box(right_ny=2, shared=True, left_handed=(), etype=HEX, moved=None) -> Hexes:
    """A gel box 0..1 x 0..1 x 0..1 of 2 x 2 x 2 hexahedra, its top (z = 1) permeable and its base fixed; with
    ``right_ny`` a second block 1..2 beside it whose shared face x = 1 has right_ny divisions along y."""
    w = Hexes()
    node = w.block("gel", (0, 0, 0), (1, 1, 1), (2, 2, 2), left_handed=left_handed, etype=etype, moved=moved)
    if right_ny != 2 or not shared:
        w.block("right", (1, 0, 0), (2, 1, 1), (2, right_ny, 2), shared=shared)
    w.face_group("top", node, ((0, 2), (0, 2)), 2)
    w.face_group("base", node, ((0, 2), (0, 2)), 0)
    return w


CASES = {  # name: (file, [words of the one-line error])
    "tetrahedra": (lambda: _box(etype=TET), ["non-hexahedral cells in cell group 'gel'", "SubdivisionAlgorithm"]),
    "left-handed": (lambda: _box(left_handed=(3,)), ["1 inverted cell(s)", "'gel'", "left-handed"]),
    "inside-out": (lambda: _box(moved={(1, 1, 1): (0.5, 0.5, 2.5)}), ["degenerate or badly distorted", "'gel'"]),
    "hanging-nodes": (lambda: _box(right_ny=3), ["not conforming", "hanging node", "inside a face"]),
    "unjoined": (lambda: _box(shared=False), ["not conforming", "distinct", "'right'"]),
    "2d-file": (bilayer, ["is not a 3D mesh", "'msh'"]),
    "not-a-grid": (lambda: _box(moved={(1, 1, 2): (0.6, 0.5, 1.0)}), ["geometry.file", "not a tensor grid"]),
    "curved": (lambda: _box(moved={(1, 1, 2): (0.5, 0.5, 1.1)}), ["geometry.surface", "neither flat"]),
    "quarter-tube": (lambda: _quarter_tube(), ["geometry.surface", "does not go all the way around"]),
}


def _quarter_tube() -> Hexes:
    """A quarter of a tube's wall (r 1..1.2, 0..90 degrees, z 0..0.2): its passage r = 1 is a partial cylinder."""
    import math

    w = Hexes()
    nt, nr = 4, 1
    pos = {(i, j, k): (r * math.cos(t), r * math.sin(t), 0.1 * k)
           for i, t in enumerate(np.linspace(0, math.pi / 2, nt + 1)) for j, r in enumerate((1.0, 1.2))
           for k in range(3)}
    node = w.block("gel", (0, 0, 0), (1, 1, 1), (nt, nr, 2), moved=pos)
    w.cells["top"] = (2, QUAD, [[node(i, 0, k), node(i + 1, 0, k), node(i + 1, 0, k + 1), node(i, 0, k + 1)]
                                for i in range(nt) for k in range(2)])
    w.face_group("base", node, ((0, nt), (0, nr)), 0)
    return w


def _run_exits_2(tmp, text: str, capsys) -> str:
    """The config ``text`` run: exit 2, one line on rank 0, no result directory (the 2D files' check)."""
    path = tmp / "c.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.barrier()
    return run_exits_2(tmp, path, capsys)


@pytest.mark.parametrize("case", list(CASES))
def test_a_malformed_hexahedral_file_exits_2_naming_the_cell_or_group(case, shared_tmp, capsys):
    make, words = CASES[case]
    path = shared_tmp / f"{case}.msh"
    if MPI.COMM_WORLD.rank == 0:
        make().write(path)
    layers = ('{ film = "film", substrate = "substrate", right = "substrate" }' if case == "2d-file" else
              '{ gel = "substrate", right = "substrate" }' if case in ("hanging-nodes", "unjoined") else
              '{ gel = "substrate" }')
    roles = '{ top = "permeable", bottom = "fixed" }' if case == "2d-file" else '{ top = "permeable", base = "fixed" }'
    err = _run_exits_2(shared_tmp, f'[geometry]\nkind = "msh-3d"\nfile = "{path}"\nlayers = {layers}\n'
                                   f'boundaries = {roles}\n', capsys)
    assert str(path) in err
    for w in words:
        assert w in err, err


def test_a_3d_file_given_as_2d_names_the_3d_kind(shared_tmp, capsys):
    path = shared_tmp / "box.msh"
    if MPI.COMM_WORLD.rank == 0:
        _box().write(path)
    err = _run_exits_2(shared_tmp, f'[geometry]\nkind = "msh"\nfile = "{path}"\nlayers = {{ gel = "substrate" }}\n'
                                   'boundaries = { top = "permeable", base = "fixed" }\n', capsys)
    assert "is a 3D mesh" in err and "'msh-3d' reads 3D meshes of hexahedra" in err


def test_a_flat_surface_asked_to_be_a_cylinder_is_refused(shared_tmp, capsys):
    path = shared_tmp / "box.msh"
    if MPI.COMM_WORLD.rank == 0:
        _box().write(path)
    err = _run_exits_2(shared_tmp, f'[geometry]\nkind = "msh-3d"\nfile = "{path}"\nsurface = "cylinder"\n'
                                   'layers = { gel = "substrate" }\nboundaries = { top = "permeable", base = "fixed" }\n',
                       capsys)
    assert "geometry.surface" in err and "'cylinder'" in err and "is flat" in err


def test_good_hexahedral_files_pass_the_checks(shared_tmp):
    """The good box, one consistently left-handed, and a hex block meshed beside it conformingly."""
    from test_msh_malformed import _merge

    files = {"box": _box(), "all-left-handed": _box(left_handed=range(8))}
    two = Hexes()
    node = two.block("gel", (0, 0, 0), (1, 1, 1), (2, 2, 2))
    two.block("right", (1, 0, 0), (2, 1, 1), (2, 2, 2))
    two.face_group("top", node, ((0, 2), (0, 2)), 2)
    files["two-blocks"] = two
    if MPI.COMM_WORLD.rank == 0:
        for name, w in files.items():
            w.write(shared_tmp / f"{name}.msh")
            result = _merge(shared_tmp / f"{name}.msh", 3)
            assert isinstance(result, tuple), f"{name}: {result}"
    MPI.COMM_WORLD.barrier()
