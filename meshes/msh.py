"""Reader of user-supplied gmsh ``.msh`` files: 2D quadrilateral or 3D hexahedral cells with named physical
groups.

:func:`merge` loads a file into the current gmsh model (pure gmsh; see :mod:`meshes`) and returns
its (cell groups, facet groups) as name -> tag, or a sentence saying what is wrong with the file.
Cell groups name the layers and facet groups the boundaries; the config maps them to materials and
boundary roles (``geometry.layers``, ``geometry.boundaries``). A 2D file is read by ``geometry.kind =
"msh"`` (:func:`check_cells`), a 3D one by ``"msh-3d"`` (:func:`check_hexahedra`).
"""

from __future__ import annotations

from pathlib import Path

import gmsh
import numpy as np

QUAD = 3  # gmsh element type of 4-node quadrilaterals
HEX = 5  # gmsh element type of 8-node hexahedra
# each hexahedron corner (gmsh order) and its three neighbours, right-handed for a positive Jacobian
HEX_CORNERS = ((0, 1, 3, 4), (1, 2, 0, 5), (2, 3, 1, 6), (3, 0, 2, 7),
               (4, 7, 5, 0), (5, 4, 6, 1), (6, 5, 7, 2), (7, 6, 4, 3))
# the six faces of a hexahedron (gmsh order), each a cycle of its corners
HEX_FACES = ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))


def merge(path: str | Path, dim: int = 2) -> tuple[dict[str, int], dict[str, int]] | str:
    """Merge the file into the current gmsh model: its (cell groups, facet groups), or a sentence
    saying what is wrong (missing, unreadable, of the other dimension than ``dim``, no physical groups of
    cells, cells other than quadrilaterals (2D) or hexahedra (3D), unusable cells or a non-conforming
    interface: :func:`check_cells`, :func:`check_hexahedra`), naming the group or cell."""
    path = Path(path)
    if not path.is_file():
        return "does not exist"
    try:
        gmsh.merge(str(path))
    except Exception as err:  # gmsh reports every parse error as a bare Exception
        return "is not a readable gmsh mesh (" + " ".join(str(err).split()) + ")"
    names = physical_names(dim)
    volume = set(gmsh.model.mesh.getElementTypes(3))
    if volume and dim == 2:
        groups = [gmsh.model.getPhysicalName(3, t) or f"group{t}" for _, t in gmsh.model.getPhysicalGroups(3)]
        return (f"is a 3D mesh (volume elements, gmsh element types {sorted(volume)}"
                + (", physical group(s) " + ", ".join(map(repr, groups)) if groups else "")
                + "); geometry.kind = 'msh' reads 2D meshes of quadrilaterals in the x-y plane, "
                "'msh-3d' reads 3D meshes of hexahedra")
    if not volume and dim == 3:
        return ("is not a 3D mesh (no volume elements); geometry.kind = 'msh-3d' reads 3D meshes of hexahedra, "
                "'msh' reads 2D meshes of quadrilaterals")
    if not names[0]:
        return f"has no {dim}D physical groups (cell groups name the layers)"
    cell_type, what = (QUAD, "quadrilateral") if dim == 2 else (HEX, "hexahedral")
    fix = ("recombine the mesh" if dim == 2 else
           "mesh it transfinite or by extrusion with recombination, or subdivide: Mesh.SubdivisionAlgorithm = 2")
    flux = "RTCF" if dim == 2 else "NCF"
    for name, tag in names[0].items():
        types = set()
        for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            types |= set(gmsh.model.mesh.getElementTypes(dim, ent))
        if types - {cell_type}:
            return (f"contains non-{what} cells in cell group {name!r} (gmsh element types "
                    f"{sorted(types)}); hydrobuckle's {flux} flux needs {what} cells ({fix})")
    types = set(gmsh.model.mesh.getElementTypes(dim))
    if types - {cell_type}:  # outside the cell groups
        return (f"contains non-{what} cells (gmsh element types {sorted(types)}); "
                f"hydrobuckle's {flux} flux needs {what} cells ({fix})")
    check = check_cells if dim == 2 else check_hexahedra
    return check(names[0], names[1]) or names


def refine(times: int) -> None:
    """Split every element of the current model uniformly ``times`` times (gmsh's own refinement: a
    quadrilateral into 4, a boundary segment into 2; the physical groups are kept). A file's entities
    carry no CAD curve, so the new nodes lie on its straight edges: the refined mesh covers exactly the
    polygon of the file, which is what a mesh refinement study of that file must compare."""
    for _ in range(times):
        gmsh.model.mesh.refine()


def _cells(cell_groups: dict[str, int], dim: int = 2):
    """(element tags, their node tags (4 a quad, 8 a hexahedron), their group names, node tag -> xyz lookup)
    of the quads (``dim`` 2) or hexahedra (3) in the cell groups of the current model."""
    tags, nodes, groups = [], [], []
    cell_type, corners = (QUAD, 4) if dim == 2 else (HEX, 8)
    for name, tag in cell_groups.items():
        for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            etypes, etags, enodes = gmsh.model.mesh.getElements(dim, ent)
            for et, t, n in zip(etypes, etags, enodes):
                if et == cell_type:
                    tags.append(np.asarray(t, dtype=np.int64))
                    nodes.append(np.asarray(n, dtype=np.int64).reshape(-1, corners))
                    groups += [name] * len(t)
    ntags, coords, _ = gmsh.model.mesh.getNodes()
    xyz = np.zeros((int(ntags.max()) + 1 if len(ntags) else 1, 3))
    xyz[np.asarray(ntags, dtype=np.int64)] = np.asarray(coords).reshape(-1, 3)
    if not tags:
        return np.empty(0, np.int64), np.empty((0, corners), np.int64), [], xyz
    return np.concatenate(tags), np.concatenate(nodes), groups, xyz


def _at(p) -> str:
    """A point as text, (x, y) or (x, y, z)."""
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"


def _corner_signs(jac, pts, etags, groups, eps: float, distorted: str, sense: tuple[str, str]) -> str | None:
    """The sentence for the first cell whose corner Jacobians ``jac`` (cells x corners, at the corners ``pts``)
    are not all of one sign beyond ``eps`` (degenerate or ``distorted``), or that has the other sign than most
    (inverted: its nodes ``sense[0]`` where they are negative, else ``sense[1]``); None if every cell is fine."""
    pos, neg = (jac > eps).all(axis=1), (jac < -eps).all(axis=1)
    bad = ~(pos | neg)
    if bad.any():
        i = int(np.argmax(bad))
        k = int(np.argmin(jac[i] * (1 if pos.sum() >= neg.sum() else -1)))
        return (f"has a degenerate or {distorted} cell {etags[i]} in group {groups[i]!r} (negative or zero "
                f"Jacobian at its corner {_at(pts[i, k])}); fix or remesh that cell")
    flipped = neg if pos.sum() >= neg.sum() else pos
    if flipped.any():
        i = int(np.argmax(flipped))
        return (f"has {int(flipped.sum())} inverted cell(s), e.g. cell {etags[i]} in group {groups[i]!r} "
                f"(centre {_at(pts[i].mean(axis=0))}): its nodes {sense[0] if neg[i] else sense[1]} unlike the "
                f"other {int(len(etags) - flipped.sum())} (negative Jacobian); reorient it "
                "(gmsh: Mesh > Reverse, or gmsh.model.mesh.reverse)")
    return None


def _hanging(n: int, c: int, where: str, xyz, etags, groups, node_cell) -> str:
    """The sentence for node ``n`` lying inside ``where`` (an edge, a face) of cell ``c`` without being its node."""
    other = node_cell[n]
    return (f"is not conforming: node {n} at {_at(xyz[n])} (cell {etags[other]}, group {groups[other]!r}) lies "
            f"inside {where} of cell {etags[c]} (group {groups[c]!r}) without being one of its nodes (a hanging "
            "node: the groups were meshed separately); mesh them together so they share the nodes of their "
            "interface")


def _boundary(facets, owner, enodes):
    """(the facets (edges or faces, as node tags) that one cell has alone, their cells, the nodes on them, node
    tag -> the first cell that has it) of cells ``enodes`` whose facets are ``facets`` owned by ``owner``."""
    _, inverse, counts = np.unique(np.sort(facets, axis=1), axis=0, return_inverse=True, return_counts=True)
    once = counts[inverse.ravel()] == 1
    node_cell: dict[int, int] = {}
    for c, row in enumerate(enodes):
        for n in row:
            node_cell.setdefault(int(n), c)
    return facets[once], owner[once], np.unique(facets[once]), node_cell


def _unjoined(bnodes, xyz, tol, named, etags, groups, node_cell) -> str | None:
    """The sentence for two distinct boundary nodes at one point (groups meshed separately, not joined) that do
    not all lie on named facet groups (a slit's two faces), or None."""
    key = np.round(xyz[bnodes] / tol).astype(np.int64)
    _, first, cnt = np.unique(key, axis=0, return_index=True, return_counts=True)
    for j in first[cnt > 1]:
        same = bnodes[(key == key[j]).all(axis=1)]
        if all(int(n) in named for n in same):  # a slit: both faces are named boundaries
            continue
        cells = [node_cell[int(n)] for n in same[:2]]
        return (f"is not conforming: nodes {int(same[0])} and {int(same[1])} are distinct but both at "
                f"{_at(xyz[same[0]])} (cells {etags[cells[0]]} and {etags[cells[1]]}, groups "
                f"{groups[cells[0]]!r} and {groups[cells[1]]!r}): the cells there are not joined; mesh the "
                "groups together (or remove duplicate nodes, gmsh: Coherence Mesh)")
    return None


def check_cells(cell_groups: dict[str, int], facet_groups: dict[str, int] | None = None) -> str | None:
    """A sentence naming the first cell that is unusable, or None: nodes off the plane z = 0, cells that
    are degenerate or not convex (a negative Jacobian at a corner), cells oriented against the rest of
    the mesh (inverted: clockwise among counter-clockwise ones, or the reverse; a mesh consistently
    clockwise is fine), and non-conforming interfaces (a node inside another cell's edge, or two
    distinct nodes at one point: cell groups meshed separately and not joined). Distinct nodes at one
    point that all lie on named facet groups are a slit (a crack's two faces, each a boundary), not an
    error."""
    etags, enodes, groups, xyz = _cells(cell_groups)
    if len(etags) == 0:
        return "has no quadrilateral cells in its cell groups " + ", ".join(map(repr, cell_groups))
    pts = xyz[enodes]  # (n, 4, 3)
    size = float(np.ptp(pts[..., :2].reshape(-1, 2), axis=0).max()) or 1.0
    tol = 1e-9 * size
    off = np.abs(pts[..., 2]) > tol
    if off.any():
        i, k = np.argwhere(off)[0]
        return (f"has a node off the plane z = 0 (node {enodes[i, k]} at z = {pts[i, k, 2]:.6g}, cell "
                f"{etags[i]} of group {groups[i]!r}); hydrobuckle needs a 2D mesh in the x-y plane")
    xy = pts[..., :2]
    cross = np.empty((len(etags), 4))
    for k in range(4):
        e1, e2 = xy[:, (k + 1) % 4] - xy[:, k], xy[:, (k - 1) % 4] - xy[:, k]
        cross[:, k] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    sense = ("run clockwise", "run counter-clockwise")
    bad = _corner_signs(cross, xy, etags, groups, tol * tol, "non-convex", sense)
    if bad:
        return bad
    return _check_conforming(etags, enodes, groups, xyz[:, :2], tol, _facet_group_nodes(facet_groups or {}))


def _facet_group_nodes(facet_groups: dict[str, int], dim: int = 1) -> set[int]:
    """Node tags of the facets (segments, or faces with ``dim`` 2) of the named facet groups of the current
    model."""
    out: set[int] = set()
    for tag in facet_groups.values():
        for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            for nodes in gmsh.model.mesh.getElements(dim, ent)[2]:
                out.update(int(n) for n in nodes)
    return out


def _check_conforming(etags, enodes, groups, xy, tol, named: set[int] = frozenset()) -> str | None:
    edges = np.sort(np.stack([enodes, np.roll(enodes, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    owner = np.repeat(np.arange(len(etags)), 4)
    bedges, bowner, bnodes, node_cell = _boundary(edges, owner, enodes)
    # a boundary node strictly inside a boundary edge: a hanging node
    order = np.argsort(xy[bnodes, 0])
    sx, sn = xy[bnodes[order], 0], bnodes[order]
    for (a, b), c in zip(bedges, bowner):
        pa, pb = xy[a], xy[b]
        lo, hi = np.searchsorted(sx, min(pa[0], pb[0]) - tol), np.searchsorted(sx, max(pa[0], pb[0]) + tol, "right")
        cand = sn[lo:hi]
        cand = cand[(cand != a) & (cand != b)]
        if not len(cand):
            continue
        d, q = pb - pa, xy[cand] - pa
        length2 = float(d @ d)
        t = (q @ d) / length2
        dist = np.abs(q[:, 0] * d[1] - q[:, 1] * d[0]) / np.sqrt(length2)
        hit = (t > 1e-9) & (t < 1 - 1e-9) & (dist < tol + 1e-9 * np.sqrt(length2))
        if hit.any():
            return _hanging(int(cand[np.argmax(hit)]), c, "an edge", xy, etags, groups, node_cell)
    return _unjoined(bnodes, xy, tol, named, etags, groups, node_cell)


def facet_group_coordinates(facet_groups: dict[str, int], names, dim: int = 2) -> np.ndarray:
    """Coordinates (N, 3) of the nodes of the facets (dimension ``dim``) of the named facet groups of the current
    model, each node once."""
    tags = set()
    for name in names:
        for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, facet_groups[name]):
            for nodes in gmsh.model.mesh.getElements(dim, ent)[2]:
                tags.update(int(n) for n in nodes)
    ntags, coords, _ = gmsh.model.mesh.getNodes()
    xyz = dict(zip((int(t) for t in ntags), np.asarray(coords).reshape(-1, 3)))
    return np.array([xyz[t] for t in sorted(tags)]).reshape(-1, 3)


def physical_names(dim: int = 2) -> tuple[dict[str, int], dict[str, int]]:
    """(cell groups, facet groups) of the current gmsh model as name -> tag: groups of dimension ``dim`` and
    ``dim - 1``."""
    cells, facets = {}, {}
    for d, tag in gmsh.model.getPhysicalGroups():
        name = gmsh.model.getPhysicalName(d, tag) or f"group{tag}"
        if d == dim:
            cells[name] = tag
        elif d == dim - 1:
            facets[name] = tag
    return cells, facets


def check_hexahedra(cell_groups: dict[str, int], facet_groups: dict[str, int] | None = None) -> str | None:
    """The 3D counterpart of :func:`check_cells`: a sentence naming the first unusable hexahedron, or None.
    Degenerate or badly distorted cells (the Jacobian of some corner, the triple product of its three edges, of
    the other sign than the cell's others or zero), cells oriented against the rest of the mesh (a left-handed
    node order among right-handed ones, or the reverse; a mesh consistently one way is fine), and
    non-conforming interfaces (a node inside another cell's face, or two distinct nodes at one point that do not
    all lie on named facet groups)."""
    etags, enodes, groups, xyz = _cells(cell_groups, dim=3)
    if len(etags) == 0:
        return "has no hexahedral cells in its cell groups " + ", ".join(map(repr, cell_groups))
    pts = xyz[enodes]  # (n, 8, 3)
    size = float(np.ptp(pts.reshape(-1, 3), axis=0).max()) or 1.0
    tol = 1e-9 * size
    jac = np.empty((len(etags), 8))
    for k, (c, a, b, d) in enumerate(HEX_CORNERS):
        jac[:, k] = np.einsum("ij,ij->i", np.cross(pts[:, a] - pts[:, c], pts[:, b] - pts[:, c]), pts[:, d] - pts[:, c])
    bad = _corner_signs(jac, pts, etags, groups, tol ** 3, "badly distorted", ("are left-handed", "are right-handed"))
    if bad:
        return bad
    return _check_conforming_3d(etags, enodes, groups, xyz, tol, _facet_group_nodes(facet_groups or {}, dim=2))


def _check_conforming_3d(etags, enodes, groups, xyz, tol, named: set[int] = frozenset()) -> str | None:
    faces = np.stack([enodes[:, list(f)] for f in HEX_FACES], axis=1).reshape(-1, 4)  # (6 n, 4) in cycle order
    owner = np.repeat(np.arange(len(etags)), 6)
    bfaces, bowner, bnodes, node_cell = _boundary(faces, owner, enodes)
    # a boundary node inside a boundary face (not one of its corners): a hanging node. Each face is split
    # into two triangles through its diagonal; a node within tol of a triangle's plane and inside it hits.
    order = np.argsort(xyz[bnodes, 0])
    sx, sn = xyz[bnodes[order], 0], bnodes[order]
    for face, c in zip(bfaces, bowner):
        P = xyz[face]
        lo, hi = np.searchsorted(sx, P[:, 0].min() - tol), np.searchsorted(sx, P[:, 0].max() + tol, "right")
        cand = sn[lo:hi]
        cand = cand[~np.isin(cand, face)]
        if not len(cand):
            continue
        Q = xyz[cand]
        inside = (Q >= P.min(axis=0) - tol).all(axis=1) & (Q <= P.max(axis=0) + tol).all(axis=1)
        cand, Q = cand[inside], Q[inside]
        for tri in ((0, 1, 2), (0, 2, 3)):
            A, B, C = P[list(tri)]
            e1, e2 = B - A, C - A
            nrm = np.cross(e1, e2)
            area2 = float(np.linalg.norm(nrm))
            if not len(cand) or area2 <= 0:
                continue
            r = Q - A
            dist = np.abs(r @ nrm) / area2
            # a node of a curved interface meshed separately lies on the curve, a sag ~ h^2 / 8R off the face's
            # chord plane: within a hundredth of the face's size counts as on it
            near = max(tol, 1e-2 * float(np.linalg.norm(P[2] - P[0])))
            # barycentric coordinates in the triangle's plane
            g = np.array([[e1 @ e1, e1 @ e2], [e1 @ e2, e2 @ e2]])
            lam = np.linalg.solve(g, np.stack([r @ e1, r @ e2]))
            eps = 1e-9
            corner = np.linalg.norm(Q[:, None, :] - P[None], axis=2).min(axis=1) <= tol  # a slit's other face
            hit = (dist < near) & (lam[0] > -eps) & (lam[1] > -eps) & (lam.sum(axis=0) < 1 + eps) & ~corner
            if hit.any():
                return _hanging(int(cand[np.argmax(hit)]), c, "a face", xyz, etags, groups, node_cell)
    return _unjoined(bnodes, xyz, tol, named, etags, groups, node_cell)
