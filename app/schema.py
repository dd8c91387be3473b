"""The building blocks of the config schema: a typed key with its default and allowed range.

Kept apart from :mod:`app.config` so that the modules that own a group of keys (geometry kinds, the
material law, loadings) can declare them without importing the config machinery.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


class ConfigError(ValueError):
    """A bad configuration value; ``str(err)`` is a one-line message naming the key."""

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(f"config key '{key}': {message}" if key else message)


@dataclass(frozen=True)
class Key:
    """One config key: its type, default, and a range check with a readable description."""

    type: type
    default: Any
    check: Callable[[Any], bool] | None = None
    allowed: str = ""
    doc: str = ""
    optional: bool = False  # default None allowed (inherit / not set)
    unit: str = ""


def gt(lo):
    return (lambda v: v > lo), f"> {lo:g}"


def ge(lo):
    return (lambda v: v >= lo), f">= {lo:g}"


def in_open(lo, hi):
    return (lambda v: lo < v < hi), f"in ({lo:g}, {hi:g})"


def in_closed(lo, hi):
    return (lambda v: lo <= v <= hi), f"in [{lo:g}, {hi:g}]"


def one_of(*options):
    return (lambda v: v in options), "one of " + ", ".join(repr(o) for o in options)


def matches(pattern: str, allowed: str):
    """A string matching the regular expression ``pattern`` whole; ``allowed`` says what that means."""
    import re

    return (lambda v: re.fullmatch(pattern, v) is not None), allowed


def key(type_, default, rng=None, doc="", optional=False, unit=""):
    check, allowed = rng if rng else (None, "")
    return Key(type_, default, check, allowed, doc, optional, unit)


def unset(k: Key) -> Key:
    """The same key with no default (None: not set, inherit, or filled in later)."""
    return dataclasses.replace(k, default=None, optional=True)
