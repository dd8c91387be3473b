"""Geometry kind ``plate``: the paper's film on a substrate in 3D, over a rectangle of length L (x) and width
W (z), y up through substrate and film as in the 2D bilayer. The four sides are on rollers (u_x = 0 on
x = 0, L; u_z = 0 on z = 0, W), the base on rollers (u_y = 0, as the 2D bilayer's; or clamped, u = 0, with
``geometry.base = "clamped"``), no flux except at the
top, where fluid enters. Its every x-y section is the 2D bilayer's mesh (:mod:`meshes.plate`), so the plane-
strain bilayer is the plate one element wide, and the exact 1D reduction of the bilayer's section is the
plate's too, with a mode exp(i k.x) critical where |k| meets the 1D margin curve."""

from __future__ import annotations

from app.geometry.base import (MEMORY_BASE_MB, MEMORY_PER_DOF_KB, CrossSection, Drive, GeometryInput, GeometryKind,
                                GeometrySetup, base_key, base_role, layer_keys, planar_cross_section)
from app.schema import ConfigError, gt, key


class Plate(GeometryKind):
    name = "plate"
    # a displacement loading moves the right side (x = L) along x. Under that uniaxial drive the in-plane base
    # state is anisotropic, so the 1D reduction over |k| that certifies a swelling plate's onset does not apply
    # (not in reduced_loadings: reported as not reducible); a plate one element wide is the plane-strain
    # bilayer under the same drive
    provides = frozenset({"drive"})
    reduced_loadings = ("swelling",)  # laterally uniform: the bilayer's planar section, modes on the lattice of |k|
    three_d = True
    # a plate a few wavelengths wide at a size whose onset (with its error bar) takes minutes on 2 cores
    mesh_defaults = {"element_size": 0.0125, "film_layers": 2}
    film_element_fraction = 1.25
    keys = {
        "length": key(float, 0.25, gt(0), "L [mm] along x (plate)", unit="mm"),
        "width": key(float, 0.25, gt(0), "W [mm] along z (plate; the film's other in-plane direction)", unit="mm"),
        **layer_keys(substrate=0.1, film=0.01),
        "base": base_key(),
    }

    def cross_section(self, geo: dict) -> CrossSection:
        return planar_cross_section(geo, width=geo["width"], drive=Drive("right", 0, geo["length"]))

    def validate(self, g: GeometryInput) -> None:
        geo, mesh = g.geometry, g.mesh
        if mesh["element_size"] > geo["length"] / 2:
            raise ConfigError("mesh.element_size", f"= {mesh['element_size']:g} is too coarse; allowed: "
                              f"<= geometry.length/2 = {geo['length'] / 2:g}")
        if mesh["element_size"] > 1.5 * geo["width"]:
            raise ConfigError("mesh.element_size", f"= {mesh['element_size']:g} is too coarse; allowed: "
                              f"<= 1.5 geometry.width = {1.5 * geo['width']:g} (one element across)")

    def estimate(self, g: GeometryInput) -> dict:
        from meshes.bilayer import film_interface_height, substrate_layer_count

        geo, mesh = g.geometry, g.mesh
        nx = max(1, round(geo["length"] / mesh["element_size"]))
        nz = max(1, round(geo["width"] / mesh["element_size"]))
        first = film_interface_height(geo["film_thickness"], mesh["film_layers"], mesh["film_grading"])
        ny = mesh["film_layers"] + substrate_layer_count(geo["substrate_thickness"], first * mesh["substrate_grading"],
                                                         mesh["substrate_grading"])
        nodes = (nx + 1) * (ny + 1) * (nz + 1)
        faces = (nx + 1) * ny * nz + nx * (ny + 1) * nz + nx * ny * (nz + 1)
        dofs = 3 * nodes + faces  # Q1 vectors at nodes, one flux per face
        # 3D fill: a direct factorization's memory grows faster than the dofs (docs/three-d.md)
        memory = MEMORY_BASE_MB + 3 * MEMORY_PER_DOF_KB * dofs / 1024
        return {"cells": nx * ny * nz, "dofs": dofs, "memory_mb": memory,
                "detail": f"{nx} x {nz} elements over the plate x {ny} layers"}

    def build(self, g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
        from app.geometry.tagged import mesh_from_builder
        from meshes import plate

        geo, mesh = g.geometry, g.mesh
        tm = mesh_from_builder(comm, "plate", plate.add_model, geo["length"], geo["width"], geo["substrate_thickness"],
                               geo["film_thickness"], mesh["element_size"], mesh["film_layers"],
                               mesh["substrate_grading"], film_grading=mesh["film_grading"], msh_path=msh_path)
        return GeometrySetup(tm, {"film": "film", "substrate": "substrate"},
                             {"left": "roller_x", "right": "roller_x", "front": "roller_z", "back": "roller_z",
                              "bottom": base_role(geo), "top": "permeable"},
                             wrinkles="plane", plot_band=6 * geo["film_thickness"],
                             drive=Drive("right", 0, geo["length"]))
