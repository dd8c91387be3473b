"""The material law interface: what a constitutive model must supply, and everything derived from it.

A law (:class:`MaterialLaw`) supplies only the physics: its free energy psi(F, s; p) per unit preswollen
reference volume, its dissipation potential, its parameters declared once (name -> :class:`app.schema.Key`
with default, range, doc and unit) and its stress-free reference state s0. Everything else is derived
here, the same way for every law:

- mu = dpsi/ds and the first Piola stress P = dpsi/dF by UFL differentiation (``ufl.diff``), as UFL
  expressions for forms and fields, and as floats (the same UFL expressions evaluated, see
  :class:`_FloatEvaluator`) for reference values such as mu0;
- the per-layer parameter record (:class:`Material`, e.g. ``Hydrogel``) with s0 and mu0, whose fields are
  the declared parameters, as are config's material keys and the per-cell parameter fields of the forms.

Plane strain: ``F`` is the 2x2 in-plane deformation gradient and the out-of-plane stretch is 1. ``p``
holds the parameters as attributes: floats (a :class:`Material`) or per-cell UFL coefficients.
A new law is one module with a :class:`MaterialLaw` subclass and one registration in
``app/model/__init__.py``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import SimpleNamespace
from typing import ClassVar

import numpy as np
import ufl
from ufl.algorithms import expand_derivatives
from ufl.algorithms.apply_algebra_lowering import apply_algebra_lowering

from app.registry import Registry
from app.schema import Key

IDENTITY = ((1.0, 0.0), (0.0, 1.0))


class MaterialLaw:
    """A constitutive model: subclass, fill in the class attributes and the three methods, register an
    instance in :data:`LAWS` (``app/model/__init__.py``)."""

    name: ClassVar[str] = ""
    material_name: ClassVar[str] = "Material"  # class name of this law's per-layer record
    params: ClassVar[dict[str, Key]] = {}  # declared once: config keys, Material fields, per-cell fields
    stiffness: ClassVar[str] = "shear_modulus"  # the parameter material.film.modulus_ratio scales

    def __init__(self):
        self.material_class = _material_class(self)
        self._floats: _FloatEvaluator | None = None

    def free_energy(self, F, s, p):
        """psi(F, s) as (bulk, constraint): psi = bulk + constraint, the constraint part (a penalty on a
        volumetric constraint) integrated with the coupling quadrature (one point per cell).

        Every law implements it (the base raises NotImplementedError). Written in UFL: mu and P are its
        derivatives (``ufl.diff``), for the forms and for floats alike.

        Args:
            F: the deformation gradient (UFL): 2x2 in plane strain (the out-of-plane stretch is 1) or 3x3.
            s: the fluid content (UFL scalar).
            p: the parameters (:attr:`params`) as attributes: floats (a :class:`Material`) or UFL coefficients
                (per-cell fields, constants).

        Returns:
            (bulk, constraint): the two UFL parts of the free energy per unit preswollen reference volume.
        """
        raise NotImplementedError

    def dissipation(self, dQ, C_n, s_n, tau, p):
        """tau * phi of the step: the dissipation potential of the fluid-volume increment dQ = tau H,
        with the previous step's right Cauchy-Green tensor C_n and fluid content s_n.

        Every law implements it (the base raises NotImplementedError).

        Args:
            dQ: the step's fluid-volume increment (a UFL vector; H = dQ / tau is the flux).
            C_n: the previous step's right Cauchy-Green tensor (in plane strain its 2x2 in-plane part).
            s_n: the previous step's fluid content.
            tau: the step size [s].
            p: the parameters as attributes, as in :meth:`free_energy`.

        Returns:
            tau * phi (UFL scalar).
        """
        raise NotImplementedError

    def reference_fluid(self, p) -> float:
        """s0: the fluid content at which F = 1 is stress-free (the layer's reference state).

        Every law implements it (the base raises NotImplementedError).

        Args:
            p: a :class:`Material` of this law (its parameters as float attributes).

        Returns:
            s0 (float).
        """
        raise NotImplementedError

    def material(self, values: dict) -> Material:
        """The per-layer record of parameter values (floats).

        Args:
            values: each declared parameter (:attr:`params`) with its value, e.g. a layer's parameters from the
                config; other keys are ignored.

        Returns:
            The :class:`Material` (of this law's :attr:`material_class`).

        Raises:
            KeyError: a declared parameter is missing from ``values``.
        """
        return self.material_class.from_dict(values)

    @property
    def floats(self) -> _FloatEvaluator:
        """The evaluator of this law's mu and P at float arguments, made on first use (it imports dolfinx
        when it first evaluates).

        Returns:
            The law's one :class:`_FloatEvaluator`.
        """
        if self._floats is None:
            self._floats = _FloatEvaluator(self)
        return self._floats


LAWS: Registry[MaterialLaw] = Registry("material law")


@dataclass(frozen=True)
class Material:
    """One layer's parameter values under a law (its fields are the law's declared parameters).

    Each law makes its own subclass (:attr:`MaterialLaw.material_class`, named
    :attr:`MaterialLaw.material_name`), a frozen dataclass with one float field per parameter; ``law`` is that
    law.
    """

    law: ClassVar[MaterialLaw]

    @classmethod
    def from_dict(cls, d: dict) -> Material:
        """The record of a mapping of parameter values.

        Args:
            d: each of the law's declared parameters with its value (converted to float); other keys are
                ignored.

        Returns:
            The record.

        Raises:
            KeyError: a declared parameter is missing from ``d``.
        """
        return cls(**{k: float(d[k]) for k in cls.law.params})

    def as_dict(self) -> dict:
        """The parameter values.

        Returns:
            Each declared parameter with its value (s0 and mu0 are not fields, so not included).
        """
        return dataclasses.asdict(self)

    @property
    def s0(self) -> float:
        """Fluid content of the stress-free reference state (the law's :meth:`MaterialLaw.reference_fluid`)."""
        return self.law.reference_fluid(self)

    @property
    def mu0(self) -> float:
        """Chemical potential of the reference state: dpsi/ds at F = 1, s = s0 [MPa].

        Evaluated by the law's :attr:`MaterialLaw.floats` (the forms' own derivative; imports dolfinx).
        """
        return chemical_potential(self, IDENTITY, self.s0)


def _material_class(law: MaterialLaw) -> type:
    cls = dataclasses.make_dataclass(law.material_name, [(name, float) for name in law.params], bases=(Material,),
                                     frozen=True, namespace={"law": law})
    cls.__module__ = type(law).__module__
    return cls


# --- derived quantities: the same UFL derivatives for forms, fields and floats ------------------


def _is_ufl(*xs) -> bool:
    return any(isinstance(x, ufl.core.expr.Expr) for x in xs)


def free_energy(mat, F, s):
    """psi(F, s) of ``mat``'s law (UFL)."""
    bulk, constraint = mat.law.free_energy(F, s, mat)
    return bulk + constraint


def chemical_potential(mat, F, s):
    """mu = dpsi/ds at fixed F: a UFL expression for UFL ``F``/``s``, a float for floats (``mat`` a
    :class:`Material`, ``F`` 2x2 numbers)."""
    if not _is_ufl(F, s):
        return mat.law.floats.chemical_potential(mat, F, s)
    F, s = ufl.variable(F), ufl.variable(s)
    return ufl.diff(free_energy(mat, F, s), s)


def first_piola(mat, F, s):
    """P = dpsi/dF (2x2 plane strain, or 3x3): UFL for UFL arguments, an array for floats."""
    if not _is_ufl(F, s):
        return mat.law.floats.first_piola(mat, F, s)
    F, s = ufl.variable(F), ufl.variable(s)
    return ufl.diff(free_energy(mat, F, s), F)


class _FloatEvaluator:
    """A law's mu and P as UFL expressions of placeholder constants (parameters, F, s), differentiated
    once and evaluated by UFL for float arguments: reference values come from the same derivative the
    forms use, not from a formula written twice. F is 2x2 (plane strain) or 3x3; each size is built once."""

    def __init__(self, law: MaterialLaw):
        self.law = law
        self._by_dim: dict = {}

    def _of(self, dim: int):
        if dim not in self._by_dim:
            from app import compat  # dolfinx only once a law is evaluated

            domain = compat.placeholder_domain()
            params = {name: ufl.Constant(domain) for name in self.law.params}
            Fc, sc = ufl.Constant(domain, shape=(dim, dim)), ufl.Constant(domain)
            F, s = ufl.variable(Fc), ufl.variable(sc)
            bulk, constraint = self.law.free_energy(F, s, SimpleNamespace(**params))
            psi = bulk + constraint
            P = _lowered(ufl.diff(psi, F))
            self._by_dim[dim] = SimpleNamespace(params=params, F=Fc, s=sc, mu=_lowered(ufl.diff(psi, s)),
                                                P=[[P[i, j] for j in range(dim)] for i in range(dim)])
        return self._by_dim[dim]

    def _mapping(self, mat, F, s):
        F = np.asarray(F, dtype=float)
        e = self._of(F.shape[0])
        values = {c: getattr(mat, name) for name, c in e.params.items()}
        values[e.F] = tuple(tuple(float(v) for v in row) for row in F)
        values[e.s] = float(s)
        return e, values

    def chemical_potential(self, mat, F, s) -> float:
        e, m = self._mapping(mat, F, s)
        return float(e.mu((), m))

    def first_piola(self, mat, F, s) -> np.ndarray:
        e, m = self._mapping(mat, F, s)
        return np.array([[float(Pij((), m)) for Pij in row] for row in e.P])


def _lowered(expr):
    return expand_derivatives(apply_algebra_lowering(expr))
