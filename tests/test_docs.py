"""The documentation's reference pages against the code they are generated from: every config key of the
schema documented and on the Configuration page, every command and option of the parser on the Command
line page, every name of the Python API on its page; every page of docs/ in the site. The site itself is
built with warnings as errors and checked in a browser by ``bash scripts/docs.sh`` (CI runs it)."""

from __future__ import annotations

import argparse
import re
import sys

import pytest
from conftest import REPO, rank_local

sys.path.insert(0, str(REPO / "docs" / "_ext"))
import hbreference  # noqa: E402

from app import config  # noqa: E402
from app.cli.parser import parser  # noqa: E402

pytestmark = rank_local
DOCS = REPO / "docs"


def test_every_config_key_is_documented_and_on_the_reference_page():
    """Each key of the schema (with the keys every registered geometry kind, law, loading and criterion
    declares) has a doc string and a row of its own, with its allowed range where it has one."""
    keys = hbreference.schema_keys()
    names = {name for name, _ in keys}
    assert len(names) == len(keys) > 80
    assert "material.film.modulus_ratio" in names and "stability.criterion" in names
    page = hbreference.config_page()
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\| `([\w.]+)` \|.*$", page, re.M)}
    undocumented = [name for name, spec in keys if not spec.doc.strip()]
    assert not undocumented, f"keys without a doc string: {undocumented}"
    assert set(rows) == names
    for name, spec in keys:
        if spec.allowed:
            assert spec.allowed.replace("|", "\\|") in rows[name], name


def test_a_key_registered_later_appears_on_the_page(monkeypatch):
    """The page is made from the schema at build time, not written by hand: a key added to a table shows
    up (the schema function patched to add one)."""
    from app import config_schema
    from app.schema import key

    real = config_schema.schema

    def more():
        s = real()
        s["time"] = {**s["time"], "made_up_key": key(float, 1.5, None, "a key added by the test")}
        return s

    monkeypatch.setattr(config_schema, "schema", more)
    assert "| `time.made_up_key` | float | `1.5` |" in hbreference.config_page()


def _options(sub: argparse.ArgumentParser) -> list[str]:
    return [opt for a in sub._actions if a.help != argparse.SUPPRESS for opt in a.option_strings]


def test_every_command_and_option_is_on_the_command_line_page():
    """Each subcommand has a section with its --help text; each visible option string appears in it;
    hidden options (argparse.SUPPRESS) do not."""
    page = hbreference.cli_page()
    subs = hbreference._subcommands(parser())
    assert set(subs) >= {"run", "validate", "study", "sweep", "converge", "reduced", "bench", "mesh", "version",
                         "warmup"}
    sections = re.split(r"^## ", page, flags=re.M)[1:]
    by_name = {re.match(r"`hydrobuckle (\S+)`", s).group(1): s for s in sections}
    assert set(by_name) == set(subs)
    for name, sub in subs.items():
        for opt in _options(sub):
            assert re.search(rf"(?<![\w-]){re.escape(opt)}(?![\w-])", by_name[name]), (name, opt)
    assert "--json-only" not in by_name["bench"]


def test_the_api_page_documents_every_exported_name():
    import app

    text = (DOCS / "reference" / "api.md").read_text()
    members = re.search(r":members: (.*)", text).group(1)
    assert {m.strip() for m in members.split(",")} == set(app.__all__)


def _toctree_entries() -> set[str]:
    entries = set()
    for page in DOCS.rglob("*.md"):
        if {"_build", "generated"} & set(page.relative_to(DOCS).parts):
            continue
        for block in re.findall(r"```\{toctree\}\n(.*?)```", page.read_text(), re.S):
            for line in block.splitlines():
                line = line.strip()
                if line and not line.startswith(":"):
                    base = DOCS if line.startswith("/") else page.parent
                    entries.add(str((base / line.lstrip("/")).resolve().relative_to(DOCS)))
    return entries


def test_every_page_is_in_the_site():
    """Every Markdown page under docs/ (and the tutorial) is reached from a toctree: a page written but
    not linked would be built and never found."""
    entries = _toctree_entries()
    excluded = {"_build", "generated", "bench"}  # bench/: hydrobuckle bench's own output, kept as data (conf.py)
    pages = {str(p.relative_to(DOCS).with_suffix("")) for p in DOCS.rglob("*.md")
             if not excluded & set(p.relative_to(DOCS).parts) and p.name != "index.md"}
    pages.add("tutorial")
    pages.add("notes/index")
    missing = pages - entries
    assert not missing, f"pages in no toctree: {sorted(missing)}"


@pytest.mark.parametrize("page", ["README.md", "docs/index.md"])
def test_the_front_pages_name_the_quick_lane_and_the_docs_command(page):
    text = (REPO / page).read_text()
    if page == "README.md":
        assert "bash scripts/test.sh --quick" in text and "bash scripts/docs.sh" in text
    else:
        assert "tutorial" in text and "reference/generated/config" in text
