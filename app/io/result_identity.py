"""What makes two configs give the same result, for resuming a run: the result-changing keys (everything but
what only decides when a run ends or what it writes), their hash, and the input files' digests."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

# Keys a resumed run may change: they decide when a run ends or what it writes, never a row before the
# checkpoint or the continuation after it (time.end: only above the checkpoint's time, see check()); reduced.*
# only sets the 1D counterpart computed after the run; stability.surface_check adds a summary entry only, and
# the trial crease (stability.creases and its parameters) is computed after the run on a mesh of its own.
FREE_KEYS = ("output", "time.end", "time.max_steps", "stability.error_estimate", "stability.surface_check", "reduced",
             "stability.creases", "stability.crease_size", "stability.crease_resolution",
             "stability.crease_fluid", "stability.crease_growth")


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v:
            out.update(_flat(v, key + "."))
        else:
            out[key] = v
    return out


def _free(key: str) -> bool:
    return any(key == f or key.startswith(f + ".") for f in FREE_KEYS)


# keys added after checkpoints were first written, with the value that means what their absence meant: left
# out of the comparison at that value, so such a checkpoint still resumes
ADDED_KEYS = {"mesh.refinements": 0}


def result_keys(cfg: dict) -> dict:
    """The flattened config without :data:`FREE_KEYS` (and :data:`ADDED_KEYS` at their old meaning): what
    must be equal for a resume."""
    return {k: v for k, v in _flat(cfg).items() if not _free(k) and not (k in ADDED_KEYS and v == ADDED_KEYS[k])}


def result_hash(cfg: dict) -> str:
    text = json.dumps(result_keys(cfg), sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()


def input_files(cfg: dict) -> dict:
    """sha256 of each input file the config names (a user mesh, ``geometry.file``): a file edited in place
    changes the result under an unchanged config."""
    out = {}
    path = cfg["geometry"].get("file")
    if path:
        try:
            out["geometry.file"] = hashlib.sha256(Path(path).read_bytes()).hexdigest()
        except OSError:
            out["geometry.file"] = None
    return out


def first_difference(old: dict, new: dict) -> str | None:
    """'key = old in the checkpoint, new now' for the first result-changing key (in the config's order)
    whose value differs, or None."""
    a, b = result_keys(old), result_keys(new)
    unset = "<unset>"
    for key in list(b) + [k for k in a if k not in b]:
        if a.get(key, unset) != b.get(key, unset):
            return f"{key} = {a.get(key, unset)!r} in the checkpoint, {b.get(key, unset)!r} now"
    return None
