"""Run configuration: a TOML file read against the schema, defaults filled in, ``--set`` overrides, validation.

The schema (:mod:`app.config_schema`) is the public contract of hydrobuckle: every key a user may write, its
type, its default and its allowed range. Validation fails with a ``ConfigError`` whose message names the key
and the allowed range in one line; the CLI turns it into exit code 2. The TOML text of a config is
:mod:`app.toml_text`'s. Both are re-exported here (``config.schema()``, ``config.dumps(cfg)``).
"""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path
from typing import Any

# the schema and the TOML text, re-exported: config.schema(), config.dumps(), ...
from app.config_schema import (  # noqa: F401
    _geometry_table,
    _kinds,
    _loadings,
    defaults,
    kind_defaults,
    law,
    leaves,
    loading_kind,
    material_keys,
    schema,
)
from app.geometry.base import GeometryInput
from app.schema import ConfigError, Key  # noqa: F401  (re-exported: config.ConfigError, config.Key)
from app.toml_text import dumps, parse_override, parse_values, toml_value  # noqa: F401


def reducible(cfg: dict) -> str:
    """'' when the config has an exact 1D reduction, else the reason naming the key
    (:func:`app.reduced.section.reducible`)."""
    from app.reduced.section import reducible as section_reducible

    return section_reducible(cfg["geometry"]["kind"], cfg["loading"]["kind"], cfg["stability"]["criterion"],
                             cfg["material"].get("layers", {}) or {})


def geometry_input(cfg: dict) -> GeometryInput:
    """What the config's geometry kind reads of it (:class:`app.geometry.base.GeometryInput`): its [geometry]
    and [mesh] tables, the loading's kind and the [material.layers] names."""
    layers = (cfg.get("material") or {}).get("layers") or {}
    return GeometryInput(cfg["geometry"]["kind"], cfg["geometry"], cfg["mesh"],
                         (cfg.get("loading") or {}).get("kind", "swelling"), tuple(layers))


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
    kind.validate(geometry_input(cfg))
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
        raise ConfigError("stability.after_onset",
                          "= 'stop' contradicts stability.stop_at_onset = false; set one of them")
    if stab["creases"] and not (kind.creases and (loading.fluid_frozen or loading.bath_equilibrium)):
        able = [lo.name for lo in _loadings() if lo.fluid_frozen or lo.bath_equilibrium]
        raise ConfigError("stability.creases", "= true needs a geometry kind with a symmetry line for the trial "
                          "crease and a loading that moves no fluid or swells from a bath; allowed: geometry.kind = "
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


