"""Malformed user .msh files, written with the gmsh API: ``hydrobuckle run`` exits 2 with one line naming
the group or cell (rank 0; nothing on the others) and creates no result directory. A conforming file of
the same shape and the built-in geometries written by ``hydrobuckle mesh`` pass the same checks."""

from __future__ import annotations

import gmsh
import pytest
from mpi4py import MPI

from app import cli
from meshes import msh

QUAD, TRI, HEX, LINE = 3, 2, 5, 1


class Writer:
    """A .msh file from explicit nodes and elements (discrete entities, one per physical group)."""

    def __init__(self):
        self.nodes: dict[tuple, int] = {}
        self.cells: dict[str, tuple[int, int, list]] = {}  # name -> (dim, element type, node lists)

    def node(self, x, y, z=0.0, shared=True) -> int:
        key = (round(x, 12), round(y, 12), round(z, 12))
        if shared and key in self.nodes:
            return self.nodes[key]
        tag = len(self.nodes) + 1
        self.nodes[key if shared else (*key, tag)] = tag
        return tag

    def grid(self, name, x0, x1, y0, y1, nx, ny, shared=True, clockwise=(), etype=QUAD):
        """nx x ny quads on a rectangle (counter-clockwise; the cells in ``clockwise`` reversed),
        or triangles (etype TRI, two per quad)."""
        own: dict = {}

        def n(i, j):
            if (i, j) not in own:
                own[(i, j)] = self.node(x0 + (x1 - x0) * i / nx, y0 + (y1 - y0) * j / ny, shared=shared)
            return own[(i, j)]

        cells = []
        for j in range(ny):
            for i in range(nx):
                q = [n(i, j), n(i + 1, j), n(i + 1, j + 1), n(i, j + 1)]
                if etype == TRI:
                    cells += [q[:3], [q[0], q[2], q[3]]]
                else:
                    cells.append(q[::-1] if len(cells) in clockwise else q)
        self.cells[name] = (2, etype, cells)
        return n

    def edge_group(self, name, pts):
        self.cells[name] = (1, LINE, [[self.node(*a), self.node(*b)] for a, b in zip(pts, pts[1:])])

    def write(self, path):
        gmsh.initialize()
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.model.add("bad")
            coords = [0.0] * (3 * len(self.nodes))
            for key, tag in self.nodes.items():
                coords[3 * (tag - 1):3 * tag] = key[:3]
            top = max(d for d, _, _ in self.cells.values())
            gmsh.model.addDiscreteEntity(top, 1)
            gmsh.model.mesh.addNodes(top, 1, list(range(1, len(self.nodes) + 1)), coords)
            nxt = len(self.nodes) + 1
            for k, (name, (dim, etype, conn)) in enumerate(self.cells.items(), start=2):
                gmsh.model.addDiscreteEntity(dim, k)
                tags = list(range(nxt, nxt + len(conn)))
                nxt += len(conn)
                gmsh.model.mesh.addElements(dim, k, [etype], [tags], [[t for c in conn for t in c]])
                gmsh.model.setPhysicalName(dim, gmsh.model.addPhysicalGroup(dim, [k]), name)
            gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
            gmsh.write(str(path))
        finally:
            gmsh.finalize()


def bilayer(right_ny=4, shared=True, clockwise=(), substrate_type=QUAD) -> Writer:
    """A film (0..1 x 0.8..1) on a substrate (0..1 x 0..0.8) — or, with right_ny, a substrate of two
    side-by-side blocks whose shared edge x = 0.5 has 4 and right_ny segments."""
    w = Writer()
    w.grid("film", 0, 1, 0.8, 1, 4, 1, clockwise=clockwise)
    w.grid("substrate", 0, 0.5, 0, 0.8, 2, 4, etype=substrate_type)
    w.grid("right", 0.5, 1, 0, 0.8, 2, right_ny, shared=shared)
    w.edge_group("top", [(0, 1), (0.25, 1), (0.5, 1), (0.75, 1), (1, 1)])
    w.edge_group("bottom", [(0, 0), (0.25, 0), (0.5, 0), (0.75, 0), (1, 0)])
    return w


def box3d() -> Writer:
    w = Writer()
    conn = [[w.node(x, y, z) for z in (0, 1) for (x, y) in ((0, 0), (1, 0), (1, 1), (0, 1))]]
    w.cells["gel"] = (3, HEX, conn)
    return w


def dart() -> Writer:
    w = Writer()
    w.cells["film"] = (2, QUAD, [[w.node(0, 0), w.node(1, 0), w.node(0.2, 0.2), w.node(0, 1)]])
    w.edge_group("top", [(0, 1), (1, 0)])
    return w


CASES = {
    "3d": (box3d, ["3D mesh", "'gel'"]),
    "non-convex": (dart, ["non-convex cell 5 in group 'film'", "corner (0.2, 0.2)"]),
    "triangles": (lambda: bilayer(substrate_type=TRI), ["non-quadrilateral", "'substrate'"]),
    "inverted": (lambda: bilayer(clockwise=(2,)), ["inverted", "'film'", "clockwise"]),
    "hanging-nodes": (lambda: bilayer(right_ny=3), ["not conforming", "hanging node", "'right'"]),
    "unjoined": (lambda: bilayer(shared=False), ["not conforming", "distinct", "'right'"]),
}
LAYERS = 'layers = { film = "film", substrate = "substrate", right = "substrate" }\n'
BOUNDARIES = 'boundaries = { top = "permeable", bottom = "fixed" }\n'


def _config(tmp, mesh_file, layers=LAYERS):
    path = tmp / "c.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(f'[geometry]\nkind = "msh"\nfile = "{mesh_file}"\n{layers}{BOUNDARIES}')
    MPI.COMM_WORLD.barrier()
    return path


def _run_exits_2(tmp, cfg_path, capsys) -> str:
    comm, out = MPI.COMM_WORLD, tmp / "out"
    assert cli.main(["run", str(cfg_path), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    if comm.rank == 0:
        assert len(err.splitlines()) == 1, err
    else:
        assert err == ""
    comm.barrier()
    assert not out.exists()
    return comm.bcast(err, root=0)


@pytest.mark.parametrize("case", list(CASES))
def test_malformed_msh_exits_2_naming_the_group_or_cell(case, shared_tmp, capsys):
    make, words = CASES[case]
    path = shared_tmp / f"{case}.msh"
    if MPI.COMM_WORLD.rank == 0:
        make().write(path)
    layers = {"3d": 'layers = { gel = "substrate" }\n',
              "non-convex": 'layers = { film = "film" }\n'}.get(case, LAYERS)
    err = _run_exits_2(shared_tmp, _config(shared_tmp, path, layers), capsys)
    assert "geometry.file" in err and str(path) in err
    for w in words:
        assert w in err, err


def test_misspelled_group_exits_2_naming_it(shared_tmp, capsys):
    path = shared_tmp / "ok.msh"
    if MPI.COMM_WORLD.rank == 0:
        bilayer().write(path)
    err = _run_exits_2(shared_tmp, _config(shared_tmp, path, LAYERS.replace("right =", "rigth =")), capsys)
    assert "geometry.layers.rigth" in err and "right" in err


def _merge(path, dim: int = 2):
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        return msh.merge(path, dim)
    finally:
        gmsh.finalize()


def test_conforming_files_pass(shared_tmp):
    """The good twin of the cases (and one consistently clockwise), and the built-in geometries."""
    comm = MPI.COMM_WORLD
    files = {"ok": shared_tmp / "ok.msh", "all-clockwise": shared_tmp / "cw.msh"}
    if comm.rank == 0:
        bilayer().write(files["ok"])
        w = Writer()
        w.grid("film", 0, 1, 0, 1, 3, 3, clockwise=range(9))
        w.edge_group("top", [(0, 1), (1, 1)])
        w.write(files["all-clockwise"])
    for kind in ("bilayer", "tube", "elliptic-tube"):
        cfg = shared_tmp / f"{kind}.toml"
        extra = "aspect_ratio = 1.5\n" if kind == "elliptic-tube" else ""
        if comm.rank == 0:
            cfg.write_text(f'[geometry]\nkind = "{kind}"\n{extra}[mesh]\nelement_size = 0.05\n')
        comm.barrier()
        files[kind] = shared_tmp / f"{kind}.msh"
        assert cli.main(["mesh", str(cfg), "-o", str(files[kind])]) == 0
    if comm.rank == 0:
        for name, path in files.items():
            result = _merge(path)
            assert isinstance(result, tuple), f"{name}: {result}"
    comm.barrier()
