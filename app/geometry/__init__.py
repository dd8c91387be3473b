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
    GeometryKind,
    GeometrySetup,
    kind_of,
)
from app.geometry.bilayer import Bilayer
from app.geometry.msh import UserMsh
from app.geometry.tube import EllipticTube, Tube

BUILTIN = (Bilayer(), Tube(), EllipticTube(), UserMsh())  # registration order = the order docs list them
for _kind in BUILTIN:
    KINDS.register(_kind)
DEFAULT_KIND = "bilayer"  # the paper's film on a substrate


def build(cfg: dict, comm, msh_path: str | None = None) -> GeometrySetup:
    """The geometry of ``cfg``; with ``msh_path`` the kind also writes its gmsh mesh."""
    return kind_of(cfg).build(cfg, comm, msh_path)


def check(cfg: dict, comm) -> None:
    """Raise ConfigError (on every rank) for input errors only the geometry's files can show, without
    building a mesh (a user .msh: missing, unreadable, groups the config names but the file lacks).
    Everything else is checked by ``config.validate``. Commands call this before they create any result."""
    kind_of(cfg).check_input(cfg, comm)
