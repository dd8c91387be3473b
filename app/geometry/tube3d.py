"""Geometry kind ``tube-3d``: the paper's bilayered tube in 3D, the circular cross-section of kind ``tube``
extruded along the axis z by a length. The passage is permeable, the outer wall rigid and impermeable, both
ends on rollers (u_z = 0, no flux), so the laterally uniform state is the plane-strain tube's, and an
axially uniform mode is the 2D tube's mode: the exact polar 1D reduction certifies the tube's onset among
the modes with no axial wave (m = 0). Whether a mode with axial half-waves (m > 0) comes first is the 3D
run's answer (each critical mode's (n around, m along the axis) is reported)."""

from __future__ import annotations

from app.geometry.base import MEMORY_BASE_MB, MEMORY_PER_DOF_KB, GeometryInput, GeometrySetup, layer_keys
from app.geometry.tube import EllipticTube, Tube, grown_at_minor_vertex
from app.schema import ConfigError, gt, in_closed, key


class Tube3D(Tube):
    name = "tube-3d"
    provides = frozenset()
    three_d = True
    # a short tube segment whose onset (with its error bar) takes minutes on 2 cores
    mesh_defaults = {"element_size": 0.01, "film_layers": 2}
    film_element_fraction = 1.0
    keys = {
        **Tube.keys,
        # a small tube (configs/tube-3d.toml): the paper's R = 1 mm is ~150k dofs a wavelength long
        "outer_radius": key(float, 0.2, gt(0), "R [mm] (tubes)", unit="mm"),
        **layer_keys(substrate=0.05, film=0.01),
        "length": key(float, 0.1, gt(0), "L_z [mm] along the axis (tube-3d)", unit="mm"),
        "axial_element_ratio": key(float, 1.0, in_closed(0.1, 10.0),
                                   "element size along the axis / mesh.element_size (tube-3d)"),
    }

    def axial_elements(self, g: GeometryInput) -> int:
        geo, mesh = g.geometry, g.mesh
        return max(1, round(geo["length"] / (mesh["element_size"] * geo["axial_element_ratio"])))

    def estimate(self, g: GeometryInput) -> dict:
        around, layers = self.section_size(g)
        nz = self.axial_elements(g)
        nodes = around * (layers + 1) * (nz + 1)
        faces = around * (layers + 1) * nz + around * layers * nz + around * layers * (nz + 1)
        dofs = 3 * nodes + faces
        memory = MEMORY_BASE_MB + 3 * MEMORY_PER_DOF_KB * dofs / 1024  # 3D fill, as the plate's
        return {"cells": around * layers * nz, "dofs": dofs, "memory_mb": memory,
                "detail": f"{around} elements around x {nz} along the axis x {layers} layers"}

    def build(self, g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
        from app.geometry.tagged import mesh_from_builder
        from meshes import tube3d
        from meshes.tube import GeometryError

        geo, mesh = g.geometry, g.mesh
        try:
            tm = mesh_from_builder(comm, "tube-3d", tube3d.add_model, geo["outer_radius"], geo["substrate_thickness"],
                                   geo["film_thickness"], mesh["element_size"], mesh["film_layers"],
                                   mesh["substrate_grading"], geo["length"], aspect_ratio=self.aspect_ratio(geo),
                                   film_grading=mesh["film_grading"],
                                   axial_elements=self.axial_elements(g), msh_path=msh_path)
        except GeometryError as err:
            raise ConfigError(err.key, str(err)) from None
        return GeometrySetup(tm, {"film": "film", "substrate": "substrate"},
                             {"inner": "permeable", "outer": "fixed", "front": "roller_z", "back": "roller_z"},
                             growth="mean_radial", wrinkles="cylinder")


class EllipticTube3D(Tube3D):
    """``elliptic-tube-3d``: the 3D tube with the elliptic passage of ``elliptic-tube`` (a/b = aspect_ratio, a b =
    r^2, semi-minor axis b along x). Growth is the inward displacement of the minor-axis vertex line (b, 0, z),
    averaged along the axis: the paper's g_c,x. No exact 1D reduction (the passage is not axisymmetric); one
    element long it is the 2D elliptic tube."""

    name = "elliptic-tube-3d"
    keys = {**Tube3D.keys, "aspect_ratio": EllipticTube.keys["aspect_ratio"]}
    reduced_loadings = ()

    def aspect_ratio(self, geo: dict) -> float:
        return geo["aspect_ratio"]

    def build(self, g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
        return grown_at_minor_vertex(super().build(g, comm, msh_path))
