"""Bad input, generated from the schema: every key of app.config.schema() (the geometry keys of each kind,
the material, film and loading keys built from the registries included) gets wrong-type values and values
just outside each documented bound (all rejected by config.resolve with a ConfigError naming the key), and
the closed ends of its range (accepted). One case per table also goes through ``hydrobuckle run``: exit 2,
one line on stderr naming the key (rank 0; nothing on the others), no result directory.

The bounds are parsed from ``Key.allowed`` and cross-checked against ``Key.check``: a key with a check
whose text this file cannot parse fails the test (extend ``_bounds``), so a new key is never skipped."""

from __future__ import annotations

import math
import re

import pytest
from conftest import rank_local
from mpi4py import MPI

from app import cli, config
from app.schema import Key

# a valid base config per geometry kind (the msh kind's file is not opened by config.resolve)
MSH_BASE = {"file": "x.msh", "layers": {"film": "film", "substrate": "substrate"},
            "boundaries": {"top": "permeable"}}
NUM = r"(-?[0-9.eE+-]+)"
# keys a closed end is only valid with (other keys' checks relate them): (key, value) -> companions
COMPANIONS = {
    ("geometry.kind", "msh"): {"geometry": MSH_BASE},
    ("geometry.kind", "msh-3d"): {"geometry": MSH_BASE},
    # splitting a file's cells applies to the msh kind only
    ("mesh.refinements", 4): {"geometry": {"kind": "msh", **MSH_BASE}},
    # a/b = 10 at the same area needs a passage of radius < R/sqrt(10): a thick substrate
    ("geometry.aspect_ratio", 10.0): {"geometry": {"outer_radius": 1.0, "substrate_thickness": 0.7,
                                                   "film_thickness": 0.02}},
}


def _spec_contexts():
    """(dotted key, spec, base user config) for every key; a geometry key once for every kind that
    uses it, with that kind's own spec."""
    sch = config.schema()
    for dotted, spec in config.leaves(sch):
        if dotted.startswith("geometry.") and dotted != "geometry.kind":
            name = dotted.split(".", 1)[1]
            for kind in config._kinds():
                if name in kind.keys:
                    geo = {"kind": kind.name, **(MSH_BASE if kind.name in ("msh", "msh-3d") else {})}
                    yield f"{dotted}[{kind.name}]", dotted, kind.keys[name], {"geometry": geo}
        else:
            yield dotted, dotted, spec, {}


def _up(x: float) -> float:
    return math.nextafter(x, math.inf)


def _down(x: float) -> float:
    return math.nextafter(x, -math.inf)


def _bounds(spec: Key):
    """(bad values just outside, good closed ends) from ``spec.allowed``."""
    text, is_int = spec.allowed, spec.type is int
    below = (lambda a: a - 1) if is_int else _down
    above = (lambda a: a + 1) if is_int else _up
    conv = int if is_int else float
    if m := re.fullmatch(rf"> {NUM}", text):
        a = conv(float(m[1]))
        return [a, below(a)], []
    if m := re.fullmatch(rf">= {NUM}", text):
        a = conv(float(m[1]))
        return [below(a)], [a]
    if m := re.fullmatch(rf"in \({NUM}, {NUM}\)", text):
        a, b = conv(float(m[1])), conv(float(m[2]))
        return [a, b], []
    if m := re.fullmatch(rf"in \[{NUM}, {NUM}\]", text):
        a, b = conv(float(m[1])), conv(float(m[2]))
        return [below(a), above(b)], [a, b]
    if text.startswith("one of "):
        return ["no-such-option"], re.findall(r"'([^']*)'", text)
    if text.startswith("matching "):  # a pattern: its first quoted example is good everywhere, these are not
        return ["2,0", "x", ""], re.findall(r"'([^']*)'", text)[:1]
    raise AssertionError(f"cannot read the allowed range {text!r}: extend _bounds")


def _wrong_types(spec: Key) -> list:
    return {float: ["1.0", True, {"x": 1}],
            int: [1.5, "3", True, {"x": 1}],
            bool: [1, "true", {"x": 1}],
            str: [1, True, {"x": 1}],
            dict: ["x", 1]}[spec.type]


def _with(base: dict, dotted: str, value) -> dict:
    user = {k: dict(v) for k, v in base.items()}
    parts = dotted.split(".")
    node = user
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = value
    return user


def _cases():
    bad, good = [], []
    for label, dotted, spec, base in _spec_contexts():
        for v in _wrong_types(spec):
            bad.append((f"{label}={v!r}", dotted, _with(base, dotted, v)))
        if spec.check is None:
            assert not spec.allowed, f"{label}: allowed text without a check"
            continue
        outside, ends = _bounds(spec)
        for v in outside:
            assert not spec.check(v), f"{label}: {v!r} passes the check but is outside {spec.allowed}"
            bad.append((f"{label}={v!r}", dotted, _with(base, dotted, v)))
        for v in ends:
            assert spec.check(v), f"{label}: {v!r} fails the check but is inside {spec.allowed}"
            extra = COMPANIONS.get((dotted, v), {})
            merged = {t: {**base.get(t, {}), **extra.get(t, {})} for t in {*base, *extra}}
            good.append((f"{label}={v!r}", dotted, _with(merged, dotted, v)))
    return bad, good


BAD, GOOD = _cases()


def test_the_sweep_covers_every_key():
    keys = {d for _, d, _, _ in _spec_contexts()}
    assert keys == {d for d, _ in config.leaves(config.schema())}
    assert {d for _, d, _ in BAD} == keys  # every key has at least a wrong-type case
    assert len(BAD) >= 200 and len(GOOD) >= 30, (len(BAD), len(GOOD))


@rank_local
@pytest.mark.parametrize("label,dotted,user", BAD, ids=[c[0] for c in BAD])
def test_bad_value_is_rejected_naming_the_key(label, dotted, user):
    with pytest.raises(config.ConfigError) as err:
        config.resolve(user)
    assert err.value.key == dotted, str(err.value)
    msg = str(err.value)
    assert "\n" not in msg and f"'{dotted}'" in msg


@rank_local
@pytest.mark.parametrize("label,dotted,user", GOOD, ids=[c[0] for c in GOOD])
def test_closed_end_of_the_range_is_accepted(label, dotted, user):
    cfg = config.resolve(user)
    node = cfg
    for p in dotted.split("."):
        node = node[p]
    expected = user
    for p in dotted.split("."):
        expected = expected[p]
    assert node == expected


def _one_per_table():
    """The first bad case of each table (geometry: of each kind; material.film apart)."""
    picked = {}
    for label, dotted, user in BAD:
        table = dotted.rsplit(".", 1)[0]
        if dotted == "geometry.kind":
            table = dotted
        elif table == "geometry":
            table += "/" + str(user.get("geometry", {}).get("kind", "bilayer"))
        if table not in picked:
            picked[table] = (label, dotted, user)
    return list(picked.values())


CLI = _one_per_table()


@pytest.mark.parametrize("label,dotted,user", CLI, ids=[c[0] for c in CLI])
def test_cli_run_exits_2_with_one_line(label, dotted, user, shared_tmp, capsys):
    comm = MPI.COMM_WORLD
    cfg_path, out = shared_tmp / "bad.toml", shared_tmp / "out"
    if comm.rank == 0:
        cfg_path.write_text(_toml(user))
    comm.barrier()
    assert cli.main(["run", str(cfg_path), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    if comm.rank == 0:
        assert len(err.splitlines()) == 1 and f"'{dotted}'" in err, err
    else:
        assert err == ""
    comm.barrier()
    assert not out.exists()


def _toml(user: dict) -> str:
    """TOML text of a user dict whose values may be of the wrong type (config.dumps writes scalars)."""
    lines = []

    def val(v):
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }"
        return config.toml_value(v)

    for table, keys in user.items():
        lines.append(f"[{table}]")
        lines += [f"{k} = {val(v)}" for k, v in keys.items()]
    return "\n".join(lines) + "\n"
