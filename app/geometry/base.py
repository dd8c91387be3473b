"""What a geometry kind is: the base class every kind fills in, the registry of kinds, and the
:class:`GeometrySetup` a kind's builder hands to the problem.

Boundary roles (mechanics + chemistry; which loading uses them how is :mod:`app.model.loading`'s):

- ``permeable``: traction-free; chemical potential prescribed (the ramp), fluid enters here;
- ``impermeable`` / ``free``: traction-free, zero normal flux;
- ``fixed``: u = 0, zero normal flux (a rigid impermeable wall);
- ``roller_x`` / ``roller_y`` / ``roller_z``: u_x = 0 / u_y = 0 / u_z = 0 (3D), zero normal flux (symmetry
  or sliding support).

Growth: ``mean_normal`` is the mean displacement of the permeable surface along the body's outward
normal there (bilayer: mean u_y of the top; tube: mean inward radial displacement of the passage);
``mean_radial`` (tubes) is the mean inward radial displacement of the passage's nodes;
``vertex`` is the inward displacement of one surface point (the elliptic passage's minor-axis vertex,
the paper's g_c,x). Wrinkles are counted ``along`` an open surface (half-waves) or ``around`` a
closed one (integer wavenumber).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from app.registry import Registry
from app.schema import ConfigError, Key, gt, key, one_of

BOUNDARY_ROLES = ("permeable", "impermeable", "free", "fixed", "roller_x", "roller_y", "roller_z")
# displacement components a role holds at zero (a 2D mesh has components 0 and 1 only)
HELD_COMPONENTS = {"fixed": (0, 1, 2), "roller_x": (0,), "roller_y": (1,), "roller_z": (2,)}


@dataclass(frozen=True)
class Drive:
    """A boundary a displacement loading may move: facet group, displacement component, and the length
    that turns an applied strain into a displacement.

    Attributes:
        group: the facet group moved (a key of :attr:`GeometrySetup.boundaries`).
        component: the displacement component it moves (0: x, 1: y, 2: z).
        length: the length [mm] an applied strain is a fraction of: the compression loading moves the group
            by -strain x length.
    """

    group: str
    component: int
    length: float


@dataclass(frozen=True)
class CrossSection:
    """A kind's exact 1D counterpart, as geometry: layers along one coordinate (each (material, start, end),
    in increasing coordinate), where fluid enters and what is held. :func:`app.factory.section` adds the
    materials and the loading (:class:`app.reduced.section.Section`, whose docstring says what each shape
    means).

    Attributes:
        shape: ``"planar"`` (the coordinate Y from the base) or ``"axisymmetric"`` (r from the passage).
        layers: (material name, start, end) of each layer [mm], in increasing coordinate.
        surface: the coordinate of the permeable surface [mm].
        base: the coordinate of the held boundary [mm].
        length: planar: the length L along the surface (wavenumber k = n pi / L); None otherwise.
        width: a 3D plate's width W (its modes: a lattice of |k|); None otherwise.
        axial: a 3D tube: mode n is its axially uniform mode, wave vector (n, 0).
        clamped: planar: the base holds both displacement components.
        drive: the boundary a displacement loading moves (compression); None: none.
    """

    shape: str  # "planar" (Y from the base) or "axisymmetric" (r from the passage)
    layers: tuple[tuple[str, float, float], ...]
    surface: float  # coordinate of the permeable surface
    base: float  # coordinate of the held boundary
    length: float | None = None  # planar: the length L along the surface (wavenumber k = n pi / L)
    width: float | None = None  # a 3D plate's width W (its modes: a lattice of |k|)
    axial: bool = False  # a 3D tube: mode n is its axially uniform mode, wave vector (n, 0)
    clamped: bool = False  # planar: the base holds both displacement components
    drive: Drive | None = None  # the boundary a displacement loading moves (compression)


def planar_cross_section(geo: dict, width: float | None = None, drive: Drive | None = None) -> CrossSection:
    """The film on its substrate, from the base (Y = 0) to the permeable surface (Y = H + w), over the length L
    (``geometry.length``); ``geometry.base = "clamped"`` holds the base in both components."""
    H, w = geo["substrate_thickness"], geo["film_thickness"]
    return CrossSection("planar", (("substrate", 0.0, H), ("film", H, H + w)), H + w, 0.0, geo["length"], width,
                        clamped=geo.get("base") == "clamped", drive=drive)


@dataclass
class GeometrySetup:
    """What a kind's builder (:meth:`GeometryKind.build`, :meth:`GeometryKind.crease_setup`) hands to the
    problem: the tagged mesh and what its groups mean.

    Attributes:
        tm: the mesh with its named cell and facet groups (:class:`app.geometry.tagged.TaggedMesh`).
        layers: cell group -> the name of the material its cells are made of (``"film"``, ``"substrate"`` or a
            [material.layers.NAME]).
        boundaries: facet group -> boundary role (:data:`BOUNDARY_ROLES`; the module docstring says what each
            role means).
        growth: the growth measure the run reports (:data:`app.model.growth.GROWTH`): ``mean_normal``,
            ``mean_radial`` or ``vertex``.
        growth_point: ``growth = "vertex"``: the surface point whose inward displacement is measured [mm] (a
            mesh node).
        growth_direction: the inward unit vector at ``growth_point``.
        wrinkles: the surface shape that counts the wrinkles (:data:`app.model.shapes.SHAPES`): ``along`` an
            open surface or ``around`` a closed one in 2D, ``plane`` or ``cylinder`` in 3D.
        plot_band: a film on a substrate: the depth under the surface [mm] the mode plot shows; None: the
            whole body.
        drive: the boundary a displacement loading moves; None: none.
        info: anything else the kind keeps with the setup.
    """

    tm: object  # app.geometry.tagged.TaggedMesh
    layers: dict[str, str]  # cell group -> material name
    boundaries: dict[str, str]  # facet group -> role
    growth: str = "mean_normal"  # a growth measure of app.model.growth.GROWTH: mean_normal, mean_radial, vertex
    growth_point: tuple[float, float] | None = None
    growth_direction: tuple[float, float] | None = None  # inward unit vector at growth_point
    wrinkles: str = "along"  # a surface shape of app.model.shapes.SHAPES: along (open), around (closed)
    plot_band: float | None = None  # bilayer: plot only this depth under the surface [mm]
    drive: Drive | None = None  # the boundary a displacement loading moves (None: none)
    info: dict = field(default_factory=dict)

    def facets_with_role(self, *roles: str) -> list[str]:
        """The facet groups with any of the given roles.

        Args:
            *roles: boundary roles (:data:`BOUNDARY_ROLES`), e.g. ``"permeable"``.

        Returns:
            The names of the facet groups whose role is one of ``roles``, in the order of :attr:`boundaries`
            (empty if none).
        """
        return [name for name, role in self.boundaries.items() if role in roles]

    def material_under(self, role: str, comm) -> str:
        """The material of most cells next to the facets of ``role``: the surface chemical potential ramp
        starts at its mu0. Without such cells: "film", or (no layer called so) the first material by name.

        Args:
            role: a boundary role (:data:`BOUNDARY_ROLES`), e.g. ``"permeable"``.
            comm: the mesh's communicator; collective: the cells of every rank count.

        Returns:
            The material's name (a value of :attr:`layers`), the same on every rank.
        """
        from app import fem_utils  # dolfinx once a mesh exists: config and validation stay light without it

        domain = self.tm.mesh
        tdim = domain.topology.dim
        domain.topology.create_connectivity(tdim - 1, tdim)
        f2c = domain.topology.connectivity(tdim - 1, tdim)
        n_owned = fem_utils.num_owned_cells(domain)
        group_of_cell = {}
        for group in self.layers:
            for c in self.tm.cells(group):
                group_of_cell[int(c)] = group
        counts: dict[str, int] = {}
        for g in self.facets_with_role(role):
            for f in self.tm.facets(g):
                for c in f2c.links(f):
                    if c < n_owned and int(c) in group_of_cell:
                        name = self.layers[group_of_cell[int(c)]]
                        counts[name] = counts.get(name, 0) + 1
        totals: dict[str, int] = {}
        for part in comm.allgather(counts):
            for k, v in part.items():
                totals[k] = totals.get(k, 0) + v
        if not totals:  # no cell touches the role's facets: the film if there is one, else any material
            names = sorted(set(self.layers.values()))
            return "film" if "film" in names else names[0]
        return max(sorted(totals), key=lambda k: totals[k])


# run/validate refuse a mesh estimated above this many cells unless --force (docs/reliability.md)
MAX_CELLS = 5_000_000
# memory of a serial run: RSS of the bilayer benchmark (docs/performance.md), 276/507/789 MB at
# 28836/73610/122222 dofs, fitted linearly; more ranks add about the base each
MEMORY_BASE_MB, MEMORY_PER_DOF_KB = 120.0, 5.5


def layer_keys(substrate: float, film: float) -> dict[str, Key]:
    """The thickness keys of a kind with a film on a substrate, with that kind's defaults [mm]."""
    return {"substrate_thickness": key(float, substrate, gt(0), "H [mm]", unit="mm"),
            "film_thickness": key(float, film, gt(0), "w [mm]", unit="mm")}


BASES = ("rollers", "clamped")


def base_key():
    """``geometry.base`` of a film on a substrate (bilayer, plate): the substrate's base on rollers (u_y = 0,
    the paper's) or clamped (u = 0); both impermeable. The laterally uniform state is the same, so the exact
    1D reduction covers both (its modes held accordingly at the base)."""
    return key(str, "rollers", one_of(*BASES), "the substrate's base: rollers (u_y = 0, the paper's) or clamped "
               "(u = 0); impermeable either way")


def base_role(geo: dict) -> str:
    """The boundary role of the substrate's base for ``geometry.base``."""
    return "fixed" if geo.get("base") == "clamped" else "roller_y"


def structured_size(along: int, layers: int, closed: bool, what: str) -> dict:
    """Cells, Q1 x RTCF dofs and memory of a structured quad mesh: ``along`` elements along the surface
    (``closed``: around a closed one) x ``layers`` element layers."""
    nodes_along = along if closed else along + 1
    dofs = 2 * nodes_along * (layers + 1) + along * (layers + 1) + nodes_along * layers  # u at nodes, flux at edges
    return {"cells": along * layers, "dofs": dofs, "memory_mb": MEMORY_BASE_MB + MEMORY_PER_DOF_KB * dofs / 1024,
            "detail": f"{along:,} elements {what} x {layers} layers"}


def size_line(est: dict) -> str:
    return (f"{est['cells']:,} cells ({est['detail']}), {est['dofs']:,} dofs, "
            f"about {est['memory_mb'] / 1024:,.1f} GB (serial)")


@dataclass(frozen=True)
class GeometryInput:
    """What a geometry kind reads of a resolved config, built at the top (:func:`app.config.geometry_input`): the
    kind's name, its [geometry] table (the kind's own keys, resolved), the [mesh] table, the loading's kind and
    the names of the config's [material.layers]. A kind never sees the whole config.

    Attributes:
        kind: ``geometry.kind``, the name of the kind.
        geometry: the [geometry] table: the kind's own keys, resolved (its defaults applied).
        mesh: the [mesh] table (element size, film layers, gradings, refinements, ...).
        loading: ``loading.kind``.
        layers: the names NAME of the config's [material.layers.NAME] tables.
    """

    kind: str
    geometry: Mapping[str, Any]
    mesh: Mapping[str, Any]
    loading: str = "swelling"
    layers: tuple[str, ...] = ()


class GeometryKind:
    """One value of ``geometry.kind``. A kind declares its keys and defaults, checks a config before
    anything runs, and builds the tagged mesh with what it means for the problem. Subclass it, then
    register an instance (:data:`KINDS`); the config schema, ``hydrobuckle mesh`` and the studies ask
    the kind, never its name."""

    name: ClassVar[str] = ""
    # geometry.* keys of this kind (besides ``kind``): default, range, doc
    keys: ClassVar[dict[str, Key]] = {}
    # this kind's defaults of mesh.element_size and mesh.film_layers
    mesh_defaults: ClassVar[dict] = {}
    # `hydrobuckle mesh` can write it as .msh (else: why not, for the message)
    exportable: ClassVar[bool] = True
    not_exportable_because: ClassVar[str] = ""
    # film-thickness studies keep film elements' shape: element size <= this x film thickness
    # (None: the kind has no film thickness to scale with)
    film_element_fraction: ClassVar[float | None] = None
    # what a loading may need from the geometry, e.g. "drive" (a boundary to move: GeometrySetup.drive)
    provides: ClassVar[frozenset[str]] = frozenset()
    # cell groups map to named materials, so [material.layers.NAME] applies
    named_materials: ClassVar[bool] = False
    # mesh.refinements (uniform splitting of every cell) applies; other kinds refine by mesh.element_size
    uniform_refinement: ClassVar[bool] = False

    def defaults(self) -> dict:
        """The kind's geometry defaults, which the config applies to every geometry.* key left unset.

        Returns:
            Each of :attr:`keys` with its default value.
        """
        return {name: k.default for name, k in self.keys.items()}

    def validate(self, g: GeometryInput) -> None:
        """Checks that relate this kind's keys to each other and to the mesh keys (ConfigError).

        Called by the config's validation, after every key has been checked on its own; the base checks
        nothing.

        Args:
            g: what the kind reads of the config.

        Raises:
            ConfigError: keys that do not fit together, naming the key to change.
        """

    def check_input(self, g: GeometryInput, comm) -> None:
        """Input errors only the kind's files can show, without building a mesh (ConfigError on every
        rank). Commands call this before they create any result.

        The base checks nothing (a kind that reads no file of the user's has nothing to check).

        Args:
            g: what the kind reads of the config.
            comm: the communicator; call on every rank.

        Raises:
            ConfigError: a file missing, unreadable or without what the config names, on every rank.
        """

    def build(self, g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
        """The tagged mesh and what it means; with ``msh_path`` also write the mesh as .msh.

        Every kind implements it (the base raises NotImplementedError).

        Args:
            g: what the kind reads of the config.
            comm: the communicator the mesh is distributed over; call on every rank.
            msh_path: where to write the gmsh mesh (``hydrobuckle mesh``); None: nothing is written.

        Returns:
            The :class:`GeometrySetup`: the mesh, its layers' materials, its boundary roles, and the growth
            and wrinkle measures.

        Raises:
            ConfigError: input the mesh builder cannot take, naming the key.
        """
        raise NotImplementedError

    def refined(self, g: GeometryInput, exponent: int, factor: float) -> tuple[float, dict]:
        """The mesh of a refinement study's level: refined ``exponent`` times by ``factor`` (coarsened if
        negative). Returns (the level's parameter, the config changes); ConfigError if there is no such
        level. The built-in kinds divide mesh.element_size by the factor and multiply mesh.film_layers by
        it, so element shapes are kept while h shrinks.

        Args:
            g: what the kind reads of the base level's config.
            exponent: the level: refined this many times, or coarsened ``-exponent`` times if negative
                (0: the base level).
            factor: the mesh ratio between neighbouring levels (2 in the convergence study).

        Returns:
            (the level's parameter, the changes of dotted config keys that give its mesh); the built-in
            kinds' parameter is the level's mesh.element_size.

        Raises:
            ConfigError: no such level (e.g. mesh.film_layers cannot be coarsened that often by ``factor``),
                naming the key.
        """
        mesh = g.mesh
        value = mesh["element_size"] / factor ** exponent
        layers = mesh["film_layers"] * factor ** exponent
        if layers < 1 or abs(layers - round(layers)) > 1e-9:
            raise ConfigError("mesh.film_layers", f"= {mesh['film_layers']} cannot be coarsened {-exponent} times "
                              f"by {factor:g}; allowed: a multiple of {factor ** -exponent:g}")
        return value, {"mesh.element_size": value, "mesh.film_layers": int(round(layers))}

    #: a 3D kind (hexahedra; its modes have wave vectors, stability.branch_modes may pick among them)
    three_d: ClassVar[bool] = False

    #: the loadings whose laterally uniform (or axisymmetric) state :meth:`cross_section` reduces exactly to
    #: 1D (app.reduced); empty: the kind has no 1D counterpart
    reduced_loadings: ClassVar[tuple[str, ...]] = ()

    def cross_section(self, geo: dict) -> CrossSection:
        """The kind's exact 1D counterpart from its resolved [geometry] table (kinds with
        :attr:`reduced_loadings`).

        Only called for a config the reduction covers; the base (a kind without a 1D counterpart) raises
        NotImplementedError.

        Args:
            geo: the resolved [geometry] table.

        Returns:
            The :class:`CrossSection`: its layers, permeable surface, held base and drive.
        """
        raise NotImplementedError

    #: a trial crease (stability.creases, app.onset.creases) can be placed: crease_setup and crease_line
    creases: ClassVar[bool] = False

    def crease_setup(self, g: GeometryInput, comm, tip_size: float, tip_radius: float,
                     tip_depth: float = 0.0) -> GeometrySetup:
        """The geometry meshed for a trial crease on a symmetry line of the body (:attr:`creases`).

        Kinds with :attr:`creases` implement it; the base raises NotImplementedError.

        Args:
            g: what the kind reads of the config.
            comm: the communicator the mesh is distributed over; call on every rank.
            tip_size: the element size [mm] at the crease's tip.
            tip_radius: the radius [mm] of the fine zone around the tip.
            tip_depth: > 0: a growing crease, fine within ``tip_radius`` of the symmetry line from the surface
                down to this depth [mm]; 0: fine around the tip alone.

        Returns:
            The :class:`GeometrySetup` of the meshed body, the symmetry line (:meth:`crease_line`) held in x.
        """
        raise NotImplementedError

    def crease_line(self, g: GeometryInput) -> float:
        """x of the symmetry line (held in x) the trial crease sits on.

        Kinds with :attr:`creases` implement it; the base raises NotImplementedError.

        Args:
            g: what the kind reads of the config.

        Returns:
            The line's x coordinate [mm].
        """
        raise NotImplementedError

    def estimate(self, g: GeometryInput) -> dict | None:
        """The mesh size from the keys alone, without meshing (:func:`structured_size`); None if unknown
        (a user's file).

        The pre-flight checks compare it with :data:`MAX_CELLS`; the base knows no size.

        Args:
            g: what the kind reads of the config.

        Returns:
            ``cells``, ``dofs``, ``memory_mb`` (a serial run) and ``detail`` (the elements along and across,
            for the message), as :func:`structured_size` gives them; or None.
        """
        return None


KINDS: Registry[GeometryKind] = Registry("geometry kind")


def kind_of(g: GeometryInput | str) -> GeometryKind:
    """The registered kind of a geometry input (or of a kind's name); ConfigError naming geometry.kind if none."""
    name = g if isinstance(g, str) else g.kind
    if name not in KINDS:
        raise ConfigError("geometry.kind", f"unsupported kind {name!r}")
    return KINDS.get(name)
