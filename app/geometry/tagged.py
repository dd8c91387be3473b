"""The tagged-mesh container and the rank-0 gmsh session shared by all builders."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import gmsh
import numpy as np

from app import compat


@dataclass
class TaggedMesh:
    """A distributed mesh with named cell regions (layers) and named boundary facets."""

    mesh: object
    cell_tags: object
    facet_tags: object
    cell_names: dict[str, int] = field(default_factory=dict)
    facet_names: dict[str, int] = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def cells(self, name: str) -> np.ndarray:
        return compat.cells_with_tag(self.cell_tags, self.cell_names[name])

    def facets(self, name: str) -> np.ndarray:
        return compat.facets_with_tag(self.facet_tags, self.facet_names[name])


@contextlib.contextmanager
def gmsh_session(comm, name: str, rank: int = 0):
    """Initialize gmsh on ``rank`` only (quiet, all-quad settings); finalize afterwards."""
    active = comm.rank == rank
    if active:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(name)
    try:
        yield active
    finally:
        if active:
            gmsh.finalize()


def add_physical(dim: int, tags: list[int], tag: int, name: str) -> None:
    gmsh.model.addPhysicalGroup(dim, list(tags), tag)
    gmsh.model.setPhysicalName(dim, tag, name)


def to_dolfinx(comm, rank: int, cell_names: dict, facet_names: dict, info: dict,
               msh_path: str | None = None) -> TaggedMesh:
    """Distribute the current gmsh model (on ``rank``) to all ranks as a TaggedMesh."""
    if comm.rank == rank and msh_path:
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(msh_path))
    mesh, ct, ft = compat.gmsh_model_to_mesh(gmsh.model, comm, rank, gdim=2)
    from app.geometry.quality import min_scaled_jacobian

    info = {**info, "min_scaled_jacobian": min_scaled_jacobian(mesh)}
    return TaggedMesh(mesh, ct, ft, dict(cell_names), dict(facet_names), info)
