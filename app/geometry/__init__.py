"""Geometries: what each ``geometry.kind`` means for the problem (tagged mesh, layer materials, boundary
roles, growth and wrinkle measures), one module per kind, all registered here.

A new kind is one module with a :class:`GeometryKind` subclass, one line in :data:`BUILTIN` below, and
its test: the config schema, validation, ``hydrobuckle mesh`` and the studies ask the registry.
"""

from __future__ import annotations

from app.geometry.base import (  # noqa: F401  (the package's interface)
    BOUNDARY_ROLES,
    HELD_COMPONENTS,
    KINDS,
    Drive,
    GeometryInput,
    GeometryKind,
    GeometrySetup,
    kind_of,
)
from app.geometry.bilayer import Bilayer
from app.geometry.msh import UserMsh, UserMsh3D
from app.geometry.plate import Plate
from app.geometry.tube import EllipticTube, Tube
from app.geometry.tube3d import EllipticTube3D, Tube3D
from app.schema import ConfigError

# registration order = the order docs list them
BUILTIN = (Bilayer(), Tube(), EllipticTube(), Plate(), Tube3D(), EllipticTube3D(), UserMsh(), UserMsh3D())
for _kind in BUILTIN:
    KINDS.register(_kind)
DEFAULT_KIND = "bilayer"  # the paper's film on a substrate


def build(g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
    """The geometry of ``g``; with ``msh_path`` the kind also writes its gmsh mesh."""
    return kind_of(g).build(g, comm, msh_path)


def check(g: GeometryInput, comm) -> None:
    """Raise ConfigError (on every rank) for input errors only the geometry's files can show, without
    building a mesh (a user .msh: missing, unreadable, groups the config names but the file lacks).
    Everything else is checked by ``config.validate``. Commands call this before they create any result."""
    kind_of(g).check_input(g, comm)


def export(g: GeometryInput, out, comm) -> str:
    """``hydrobuckle mesh``: build the geometry of ``g`` and write its gmsh mesh to ``out``; the line that
    says what was written (cell and facet groups). A kind without a gmsh model of its own (a user's .msh) is
    a ConfigError naming geometry.kind."""
    from pathlib import Path

    kind = kind_of(g)
    if not kind.exportable:
        able = [k.name for k in KINDS if k.exportable]
        raise ConfigError("geometry.kind", f"{kind.name!r} {kind.not_exportable_because}; allowed here: "
                          + ", ".join(able))
    out = Path(out)
    if comm.rank == 0:
        out.parent.mkdir(parents=True, exist_ok=True)
    tm = kind.build(g, comm, msh_path=str(out)).tm
    return (f"wrote {out}: cell groups {sorted(tm.cell_names)}, facet groups {sorted(tm.facet_names)}; "
            f"{tm.info}")
