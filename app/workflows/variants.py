"""Configs derived from a resolved config for runs that serve another command.

A refinement level (``converge``), a companion run of the error estimate and a benchmark size are
all "this config, changed a little, without fields.xdmf": one deep copy, the changes, the field output
switched off, and a validation, so a derived config is as checked as a user's.
"""

from __future__ import annotations

import copy

from app import config


def variant(cfg: dict, changes: dict | None = None) -> dict:
    """A validated copy of ``cfg`` with ``changes`` (dotted key -> value) and ``output.fields = false``."""
    c = copy.deepcopy(cfg)
    for key, value in {"output.fields": False, **(changes or {})}.items():
        config.set_dotted(c, key, value)
    config.validate(c)
    return c
