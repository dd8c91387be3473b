"""Run configuration: the TOML schema with defaults, validation and ``--set`` overrides.

The schema is the public contract of hydrobuckle: every key a user may write, its type, its
default and its allowed range. Validation fails with a ``ConfigError`` whose message names the
key and the allowed range in one line; the CLI turns it into exit code 2.
"""

from __future__ import annotations

import copy
import math
import numbers
import tomllib
from pathlib import Path
from typing import Any

from app.geometry.keys import MESH
from app.io.keys import OUTPUT
from app.model.keys import QUADRATURE
from app.onset.keys import STABILITY
from app.reduced.keys import KEYS as REDUCED
from app.schema import ConfigError, Key, unset  # noqa: F401  (re-exported: config.ConfigError, config.Key)
from app.schema import gt as _gt
from app.schema import key as _key
from app.schema import one_of as _one_of
from app.solvers.keys import SOLVER, TIME

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


def reducible(cfg: dict) -> str:
    """'' when the config has an exact 1D reduction, else the reason naming the key
    (:func:`app.reduced.section.reducible`)."""
    from app.reduced.section import reducible as section_reducible

    return section_reducible(cfg["geometry"]["kind"], cfg["loading"]["kind"], cfg["stability"]["criterion"],
                             cfg["material"].get("layers", {}) or {})


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


def read(path: str | Path) -> dict:
    """A config file's own tables, as written (not merged, not validated)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError("", f"config file '{path}' does not exist")
    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ConfigError("", f"config file '{path}' is not valid TOML: {err}") from None


def load(path: str | Path, overrides: list[str] | None = None) -> dict:
    """Read, merge with defaults, apply ``--set`` overrides and validate a config file."""
    return resolve(read(path), overrides)


def resolve(user: dict, overrides: list[str] | None = None) -> dict:
    """Merge a user dict and overrides into the defaults, validating every key."""
    cfg = defaults()
    _merge(cfg, user, schema(), prefix="")
    for item in overrides or []:
        key, value = parse_override(item)
        set_dotted(cfg, key, value)
    _apply_kind_defaults(cfg)
    validate(cfg)
    return cfg


def _apply_kind_defaults(cfg: dict) -> None:
    name = cfg["geometry"].get("kind")
    if name not in _kinds():
        return  # validate() reports the bad kind
    kind = _kinds().get(name)
    _check_unused_geometry_keys(cfg, kind)
    for table, values in (("geometry", kind.defaults()), ("mesh", kind.mesh_defaults)):
        for key, value in values.items():
            if cfg[table].get(key) is None:
                cfg[table][key] = copy.deepcopy(value)


def _check_unused_geometry_keys(cfg: dict, kind) -> None:
    """A geometry key the kind does not use must stay unset."""
    for name in _geometry_table():
        if name != "kind" and name not in kind.keys and cfg["geometry"].get(name) is not None:
            raise ConfigError(f"geometry.{name}", f"is not used by geometry.kind = {kind.name!r}; its keys are: "
                              + ", ".join(sorted(kind.keys)))


def parse_values(text: str, key: str = "--values") -> list:
    """Comma-separated values, each read as a TOML value (else a string); a ConfigError naming ``key`` when
    there is none."""
    out = [parse_override(f"v={item.strip()}")[1] for item in text.split(",") if item.strip()]
    if not out:
        raise ConfigError(key, "needs at least one value, e.g. --values 0.01,0.02")
    return out


def parse_override(item: str) -> tuple[str, Any]:
    """``KEY=VALUE`` with VALUE parsed as a TOML value (bare words are taken as strings)."""
    if "=" not in item:
        raise ConfigError(item, "--set expects KEY=VALUE, e.g. --set material.film.modulus_ratio=20")
    key, raw = item.split("=", 1)
    key, raw = key.strip(), raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


def set_dotted(cfg: dict, key: str, value: Any) -> None:
    """Set a dotted key after checking that the schema knows it."""
    parts = key.split(".")
    spec: Any = schema()
    node = cfg
    for i, part in enumerate(parts):
        if isinstance(spec, Key) and spec.type is dict:  # free-form table: geometry.boundaries.NAME
            table = node.get(parts[i - 1]) or {}
            node[parts[i - 1]] = table
            _set_nested(table, parts[i:], value)
            return
        if not isinstance(spec, dict) or part not in spec:
            raise ConfigError(key, f"unknown key; known keys here: {_known(spec)}")
        spec = spec[part]
        if i < len(parts) - 1 and not (isinstance(spec, Key) and spec.type is dict):
            node = node[part]
    if isinstance(spec, dict):
        raise ConfigError(key, "is a table, set one of its keys: " + _known(spec))
    node[parts[-1]] = value


def _set_nested(table: dict, parts: list[str], value: Any) -> None:
    for part in parts[:-1]:
        table = table.setdefault(part, {})
    table[parts[-1]] = value


def _known(spec) -> str:
    if not isinstance(spec, dict):
        return "(none)"
    return ", ".join(sorted(spec))


def _merge(cfg: dict, user: dict, schema: dict, prefix: str) -> None:
    for name, value in user.items():
        key = f"{prefix}{name}"
        if name not in schema:
            raise ConfigError(key, f"unknown key; known keys here: {_known(schema)}")
        spec = schema[name]
        if isinstance(spec, dict):
            if not isinstance(value, dict):
                raise ConfigError(key, "must be a table")
            _merge(cfg[name], value, spec, prefix=key + ".")
        else:
            if isinstance(value, dict) and spec.type is not dict:
                raise ConfigError(key, f"must be a {spec.type.__name__}, not a table")
            cfg[name] = value


def _check_value(key: str, spec: Key, value: Any) -> Any:
    if value is None:
        if spec.optional:
            return None
        raise ConfigError(key, "must be set")
    if spec.type is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(key, f"must be a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(key, f"must be finite, got {value!r}")
    elif spec.type is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(key, f"must be an integer, got {value!r}")
    elif spec.type is bool:
        if not isinstance(value, bool):
            raise ConfigError(key, f"must be true or false, got {value!r}")
    elif spec.type is str:
        if not isinstance(value, str):
            raise ConfigError(key, f"must be a string, got {value!r}")
    elif spec.type is dict:
        if not isinstance(value, dict):
            raise ConfigError(key, f"must be a table, got {value!r}")
    if spec.check is not None and not spec.check(value):
        raise ConfigError(key, f"= {value!r} is out of range; allowed: {spec.allowed}")
    return value


def _validate_tree(cfg: dict, schema: dict, prefix: str) -> None:
    for name, spec in schema.items():
        key = f"{prefix}{name}"
        if isinstance(spec, dict):
            _validate_tree(cfg[name], spec, key + ".")
        else:
            cfg[name] = _check_value(key, spec, cfg.get(name))


def validate(cfg: dict) -> None:
    """Type and range checks per key, then the checks that relate keys to each other."""
    sch = schema()
    kind = _validate_geometry(cfg, sch["geometry"])
    _validate_tree(cfg, {k: v for k, v in sch.items() if k != "geometry"}, "")
    time, film = cfg["time"], cfg["material"]["film"]
    stiffness = law(cfg).stiffness
    if film.get(stiffness) is not None and film.get("modulus_ratio") is not None:
        raise ConfigError(f"material.film.{stiffness}",
                          f"set either material.film.{stiffness} or material.film.modulus_ratio, not both "
                          "(use --set material.film.modulus_ratio=... alone, or remove it from the file)")
    if cfg["mesh"]["refinements"] and not kind.uniform_refinement:
        files = " and ".join(repr(k.name) for k in _kinds() if k.uniform_refinement)
        raise ConfigError("mesh.refinements", f"= {cfg['mesh']['refinements']} applies to geometry.kind = {files} "
                          f"only; allowed for {kind.name!r}: 0 (refine it with mesh.element_size and "
                          "mesh.film_layers)")
    kind.validate(cfg)
    if kind.three_d and cfg["stability"]["creases"]:  # the trial crease is a 2D method
        raise ConfigError("stability.creases", f"= true is 2D only; allowed for geometry.kind = '{kind.name}': "
                          "false (docs/three-d.md, known gaps)")
    if kind.three_d and cfg["stability"]["contact"] and cfg["stability"]["contact_energy"] == "penalty":
        raise ConfigError("stability.contact_energy", f"= 'penalty' is 2D only; allowed for geometry.kind = "
                          f"'{kind.name}': 'barrier' or 'auto' (docs/creases.md)")
    if kind.named_materials:
        _validate_material_layers(cfg, sch)
    loading = _loadings().get(cfg["loading"]["kind"])
    if not loading.needs <= kind.provides:
        able = [k.name for k in _kinds() if loading.needs <= k.provides]
        allowed = [lo.name for lo in _loadings() if lo.needs <= kind.provides]
        raise ConfigError("loading.kind", f"{loading.name!r} needs geometry.kind = " + " or ".join(map(repr, able))
                          + f"; allowed for {kind.name!r}: " + ", ".join(map(repr, allowed)))
    stab = cfg["stability"]
    if stab["after_onset"] == "stop" and not stab["stop_at_onset"]:
        raise ConfigError("stability.after_onset", "= 'stop' contradicts stability.stop_at_onset = false; set one of them")
    if stab["creases"] and not (kind.creases and (loading.fluid_frozen or loading.bath_equilibrium)):
        able = [lo.name for lo in _loadings() if lo.fluid_frozen or lo.bath_equilibrium]
        raise ConfigError("stability.creases", f"= true needs a geometry kind with a symmetry line for the trial "
                          f"crease and a loading that moves no fluid or swells from a bath; allowed: geometry.kind = "
                          + " or ".join(repr(k.name) for k in _kinds() if k.creases)
                          + " with loading.kind = " + " or ".join(map(repr, able)))
    if stab["creases"] and stab["crease_fluid"] == "transient" and not loading.fluid_frozen:
        why = reducible(cfg)
        if why:
            raise ConfigError("stability.crease_fluid", "= 'transient' takes the run's content from its exact 1D "
                              f"transient, which this config does not have ({why}); allowed: 'drained', 'undrained'")
    if stab["branch_modes"] != "1" and not kind.three_d:
        raise ConfigError("stability.branch_modes", f"= {stab['branch_modes']!r}: wave vectors pick a branch of a 3D "
                          "multiple onset; allowed for " + repr(kind.name) + ": '1' (3D kinds: "
                          + ", ".join(repr(k.name) for k in _kinds() if k.three_d) + ")")
    if stab["imperfection"] == 0.0:
        raise ConfigError("stability.imperfection", "= 0 is out of range; allowed: [-1, 1] except 0 (the sign picks "
                          "the direction along the mode)")
    if time["dt_initial"] > time["dt_max"]:
        raise ConfigError("time.dt_initial", f"= {time['dt_initial']:g} must be <= time.dt_max = {time['dt_max']:g}")
    if time["dt_min"] > time["dt_initial"]:
        raise ConfigError("time.dt_min", f"= {time['dt_min']:g} must be <= time.dt_initial = {time['dt_initial']:g}")
    if time["dt_initial"] > time["end"]:
        raise ConfigError("time.dt_initial", f"= {time['dt_initial']:g} must be <= time.end = {time['end']:g}")


def _validate_geometry(cfg: dict, table: dict):
    """The geometry table: its kind, then each key with the kind's own spec (keys it does not use must
    be unset). Returns the kind."""
    geo = cfg["geometry"]
    geo["kind"] = _check_value("geometry.kind", table["kind"], geo.get("kind"))
    kind = _kinds().get(geo["kind"])
    _check_unused_geometry_keys(cfg, kind)
    for name, spec in table.items():
        if name != "kind":
            geo[name] = _check_value(f"geometry.{name}", kind.keys.get(name, spec), geo.get(name))
    return kind


def _validate_material_layers(cfg: dict, sch: dict) -> None:
    """[material.layers.NAME] tables: each like [material.film]."""
    film_keys = sch["material"]["film"]
    for name, table in (cfg["material"].get("layers") or {}).items():
        if not isinstance(table, dict):
            raise ConfigError(f"material.layers.{name}", "must be a table of material keys")
        for k, v in table.items():
            spec = film_keys.get(k)
            if spec is None:
                raise ConfigError(f"material.layers.{name}.{k}", "unknown key; known keys here: "
                                  + _known(film_keys))
            table[k] = _check_value(f"material.layers.{name}.{k}", spec, v)


def layer_parameters(cfg: dict, name: str) -> dict:
    """Material parameters of a named layer: substrate values with that layer's overrides."""
    if name == "substrate":
        return substrate_parameters(cfg)
    if name == "film":
        return film_overrides(cfg)
    return _with_overrides(cfg, cfg["material"]["layers"][name])


def _with_overrides(cfg: dict, table: dict) -> dict:
    mat, lw = cfg["material"], law(cfg)
    out = {k: mat[k] for k in lw.params}
    for k in lw.params:
        if table.get(k) is not None:
            out[k] = table[k]
    if table.get(lw.stiffness) is None:
        ratio = table.get("modulus_ratio")
        out[lw.stiffness] = mat[lw.stiffness] * (1.0 if ratio is None else ratio)
    return out


def film_overrides(cfg: dict) -> dict:
    """The film's material parameters: substrate values with the film's overrides applied."""
    return _with_overrides(cfg, cfg["material"]["film"])


def substrate_parameters(cfg: dict) -> dict:
    mat = cfg["material"]
    return {k: mat[k] for k in law(cfg).params}


# --- TOML writing (tomllib reads only) -------------------------------------------------------


def toml_value(v: Any) -> str:
    """TOML text of one value: what dumps() writes and what a --set override takes."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, numbers.Integral):
        return str(int(v))
    if isinstance(v, numbers.Real):
        return repr(float(v))  # a numpy float's repr is "np.float64(...)" under numpy 2
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps(cfg: dict) -> str:
    """TOML text of a nested dict of scalars (None values are left out)."""
    lines: list[str] = []

    def table(d: dict, prefix: str) -> None:
        scalars = {k: v for k, v in d.items() if not isinstance(v, dict) and v is not None}
        if prefix and (scalars or not d):  # an empty table (e.g. a material with no own keys) is kept
            lines.append(f"[{prefix}]")
        for k, v in scalars.items():
            lines.append(f"{k} = {toml_value(v)}")
        if scalars or (prefix and not d):
            lines.append("")
        for k, v in d.items():
            if isinstance(v, dict):
                table(v, f"{prefix}.{k}" if prefix else k)

    table(cfg, "")
    return "\n".join(lines)
