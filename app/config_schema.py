"""The config schema: every key a user may write, its type, default and allowed range, table by table.

Each component below config declares its own keys (geometry/keys.py, model/keys.py, solvers/keys.py,
onset/keys.py, reduced/keys.py); the [output] table, read by the writer above config (io), is declared here;
the geometry, material, loading and stability tables are built from the
registered geometry kinds, material laws, loadings and criteria each time the schema is asked for, so one
registered later (by a test, a plugin) is part of it at once. :mod:`app.config` reads and checks a config
against it.
"""

from __future__ import annotations

import copy

from app.geometry.keys import MESH
from app.model.keys import QUADRATURE
from app.onset.keys import STABILITY
from app.reduced.keys import KEYS as REDUCED
from app.schema import Key, ge, unset
from app.schema import gt as _gt
from app.schema import key as _key
from app.schema import one_of as _one_of
from app.solvers.keys import SOLVER, TIME

#: the [output] keys: what a run writes (app.io.output.OutputSettings reads them)
OUTPUT: dict[str, Key] = {
    "fields": _key(bool, True, None, "write fields.xdmf"),
    "every": _key(int, 1, ge(1), "write fields every n accepted steps"),
    "plot": _key(bool, True, None, "write history.png"),
    "checkpoint_every": _key(int, 10, ge(0), "write checkpoint.npz every n accepted steps (and when "
                             "interrupted), for 'run --resume'; 0 = off"),
}

_STATIC: dict[str, dict[str, Key] | dict] = {
    "geometry": {},  # built from the registered geometry kinds: see _geometry_table
    "mesh": {**MESH, **QUADRATURE},
    "material": {},  # built from the registered material laws: see _material_table
    "loading": {},  # built from the registered loadings: see _loading_table
    "time": TIME,
    "solver": SOLVER,
    "stability": STABILITY,  # with the registered criteria: see _stability_table
    "reduced": REDUCED,
    "output": OUTPUT,
}
"""The tables in the order a resolved config lists them; each component declares its own keys."""


def schema() -> dict:
    """The whole schema: the static tables above, with the geometry, material and loading tables built
    from the registered geometry kinds, material laws and loadings (so one registered later, e.g. by a
    test, is part of it at once)."""
    return {**_STATIC, "stability": _stability_table(), "reduced": dict(REDUCED), "geometry": _geometry_table(),
            "material": _material_table(), "loading": _loading_table()}


def _stability_table() -> dict:
    """The static [stability] keys with ``criterion`` (one of the registered criteria) and every criterion's
    parameters after ``eigen_every``."""
    from app.onset import criteria

    crits = criteria.CRITERIA
    table: dict[str, Key] = {}
    for name, spec in _STATIC["stability"].items():
        table[name] = spec
        if name != "eigen_every":
            continue
        table["criterion"] = _key(str, criteria.DEFAULT, _one_of(*crits.names()),
                                  "which perturbations count: " + ", ".join(c.doc for c in crits))
        for crit in crits:
            for key_name, key_spec in crit.keys.items():
                if key_name in _STATIC["stability"] or key_name == "criterion":
                    raise ValueError(f"stability criterion {crit.name!r} declares stability.{key_name}, a key "
                                     "of the [stability] table")
                if key_name in table and table[key_name].type is not key_spec.type:
                    raise ValueError(f"stability.{key_name}: criteria declare it with different types")
                table.setdefault(key_name, key_spec)
    return table


def _kinds():
    from app import geometry

    return geometry.KINDS


def _geometry_table() -> dict:
    """``kind`` and the union of every registered kind's keys, unset: a kind's defaults are applied
    once the kind is known (:func:`_apply_kind_defaults`)."""
    from app import geometry

    kinds = _kinds()
    table: dict[str, Key] = {"kind": _key(str, geometry.DEFAULT_KIND, _one_of(*kinds.names()),
                                          "the geometry (docs/geometries.md); its keys' defaults depend on it")}
    for kind in kinds:
        for name, spec in kind.keys.items():
            if name == "kind":
                raise ValueError(f"geometry kind {kind.name!r} declares the key 'kind'")
            if name in table and table[name].type is not spec.type:
                raise ValueError(f"geometry.{name}: kinds declare it with different types")
            table.setdefault(name, unset(spec))
    return table


def _laws():
    from app.model import material

    return material.LAWS


def law(cfg: dict):
    """The material law of a resolved config."""
    from app import model

    return _laws().get(cfg["material"].get("law") or model.DEFAULT_LAW)


def material_keys() -> dict[str, Key]:
    """The parameters of every registered law, each declared once by its law (a name two laws share
    is the first one's)."""
    keys: dict[str, Key] = {}
    for lw in _laws():
        for name, spec in lw.params.items():
            if name in keys and keys[name].type is not spec.type:
                raise ValueError(f"material.{name}: laws declare it with different types")
            keys.setdefault(name, spec)
    return keys


def _material_table() -> dict:
    from app import model

    params = material_keys()
    return {
        "law": _key(str, None, _one_of(*_laws().names()),
                    f"the material law of every layer (unset: {model.DEFAULT_LAW!r})", optional=True),
        **params,
        "layers": _key(dict, None, None, "msh: more named layer materials, each like [material.film]",
                       optional=True),
        "film": {
            "modulus_ratio": _key(float, 8.0, _gt(0), "gamma_f/gamma_s: the film's stiffness over the substrate's",
                                  optional=True),
            **{k: unset(v) for k, v in params.items()},
        },
    }


def _loadings():
    from app.model import loading

    return loading.LOADINGS


def loading_kind(cfg: dict):
    """The loading class a config names (:data:`app.model.loading.LOADINGS`)."""
    return _loadings().get(cfg["loading"]["kind"])


def _loading_table() -> dict:
    """``kind`` and every registered loading's keys with their defaults (a loading reads its own)."""
    from app.model import loading

    table: dict[str, Key] = {"kind": _key(str, loading.DEFAULT_LOADING, _one_of(*_loadings().names()),
                                          "the loading: swelling through the permeable surface (the paper's), or "
                                          "compression (bilayer; diffusion off, the right edge moved)")}
    for lo in _loadings():
        for name, spec in lo.keys.items():
            if name in table and table[name] is not spec:
                raise ValueError(f"loading.{name}: loadings declare it differently")
            table[name] = spec
    return table


def kind_defaults() -> dict:
    """kind -> {"geometry": its keys' defaults, "mesh": its mesh-key defaults}."""
    return {k.name: {"geometry": k.defaults(), "mesh": dict(k.mesh_defaults)} for k in _kinds()}


def leaves(table: dict | None = None, prefix: str = ""):
    """Every key of ``table`` (default: the whole :func:`schema`) as (dotted name, :class:`~app.schema.Key`),
    in the order a resolved config lists them (the docs' reference page, the bad-input sweep)."""
    for name, spec in (schema() if table is None else table).items():
        if isinstance(spec, dict):
            yield from leaves(spec, f"{prefix}{name}.")
        else:
            yield f"{prefix}{name}", spec


def defaults() -> dict:
    """The default configuration (geometry keys unset until the kind's defaults are applied)."""
    return _defaults(schema())


def _defaults(schema: dict) -> dict:
    out = {}
    for name, spec in schema.items():
        out[name] = _defaults(spec) if isinstance(spec, dict) else copy.deepcopy(spec.default)
    return out
