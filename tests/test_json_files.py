"""One JSON writer and one atomic write (app/io/writes.py): every result file is standard JSON (a reader
outside Python takes it: NaN and infinities as null, numpy values as numbers), a checkpoint's JSON keeps
them for Python's exact round trip, and a whole file replaced goes through one durable rename.

References: the JSON standard (``json.loads`` with ``parse_constant`` refusing NaN/Infinity, as strict
readers do), the values written, and the files left on the disk."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from app.io import writes

VALUES = {"g_c_um": 6.74, "missing": float("nan"), "far": float("inf"), "near": -float("inf"),
          "n": np.int64(19), "x": np.float64(0.5), "flag": np.bool_(True), "pair": (1, 2.0),
          "field": np.array([[1.0, np.nan], [3.0, 4.0]]), "where": Path("results/a"), "none": None,
          "nested": [{"t": np.float32(0.25), "k": (np.int32(3), float("nan"))}]}


def strict(text: str):
    """``json.loads`` as a reader that knows only standard JSON."""
    def refuse(name):
        raise ValueError(f"not JSON: {name}")
    return json.loads(text, parse_constant=refuse)


def test_a_result_file_is_standard_json_with_null_for_what_is_not_a_number(tmp_path):
    path = tmp_path / "summary.json"
    writes.write_json(path, VALUES)
    text = path.read_text()
    assert text.endswith("\n")
    got = strict(text)
    assert got["missing"] is None and got["far"] is None and got["near"] is None
    assert got["n"] == 19 and type(got["n"]) is int and got["flag"] is True
    assert got["x"] == 0.5 and got["pair"] == [1, 2.0] and got["where"] == "results/a"
    assert got["field"] == [[1.0, None], [3.0, 4.0]]
    assert got["nested"] == [{"t": 0.25, "k": [3, None]}]
    assert got["g_c_um"] == 6.74  # a finite float exactly (repr round trip)


def test_a_checkpoints_json_keeps_nan_and_infinities_exactly():
    text = writes.json_text(VALUES, exact=True, indent=None)
    with pytest.raises(ValueError, match="not JSON"):
        strict(text)  # Python's extension, read back only by hydrobuckle
    got = json.loads(text)
    assert math.isnan(got["missing"]) and got["far"] == math.inf and got["near"] == -math.inf
    assert math.isnan(got["nested"][0]["k"][1]) and math.isnan(got["field"][0][1])
    assert got["x"] == 0.5 and got["g_c_um"] == 6.74


@pytest.mark.parametrize("exact", [False, True])
def test_a_value_json_cannot_hold_is_refused_by_its_type(exact):
    with pytest.raises(TypeError, match="cannot write set as JSON"):
        writes.json_text({"cases": {1, 2}}, exact=exact)
    with pytest.raises(TypeError, match="cannot write complex as JSON"):
        writes.json_text([1j], exact=exact)


def test_a_replaced_file_is_whole_and_leaves_nothing_aside(tmp_path):
    path = tmp_path / "study.json"
    path.write_text("old\n")
    writes.write_json(path, {"rows": [1, 2]})
    assert strict(path.read_text()) == {"rows": [1, 2]}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study.json"]

    def broken(tmp):
        Path(tmp).write_text("{half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        writes.replace_file(path, broken)
    assert strict(path.read_text()) == {"rows": [1, 2]}  # the previous file, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study.json"]


def test_commit_renames_a_file_written_in_parts(tmp_path):
    final = tmp_path / "checkpoint.zip"
    tmp = writes.aside(final)
    with open(tmp, "wb") as f:
        f.write(b"part one ")
        f.write(b"part two")
    writes.commit(tmp, final)
    assert final.read_bytes() == b"part one part two" and not tmp.exists()
