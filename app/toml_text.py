"""TOML text: a value as TOML (what a resolved config.toml holds and a ``--set`` override takes), a nested
dict as a TOML document, and ``KEY=VALUE`` / comma-separated values read back."""

from __future__ import annotations

import numbers
import tomllib
from typing import Any

from app.schema import ConfigError


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
