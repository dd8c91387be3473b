"""The reference pages generated from the code when the docs build: every config key from the schema
(:func:`app.config.schema`, with each geometry kind's own defaults) and every command from the argparse
parser (:func:`app.cli.parser.parser`). Written into ``docs/reference/generated/`` on ``builder-inited``
(not kept in git), so the pages cannot drift from the code. ``tests/test_docs.py`` checks that every key
and command appears."""

from __future__ import annotations

import argparse
from pathlib import Path

GENERATED = Path(__file__).resolve().parent.parent / "reference" / "generated"


def schema_keys() -> list[tuple[str, object]]:
    """Every key of the config schema as (dotted name, :class:`app.schema.Key`), in the resolved order."""
    from app import config

    return list(config.leaves())


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _default(name: str, spec, kinds: dict) -> str:
    table, _, key = name.partition(".")
    if table in ("geometry", "mesh"):
        per_kind = {k: d[table].get(key) for k, d in kinds.items() if d[table].get(key) is not None}
        if per_kind and spec.default is None:
            return "; ".join(f"{k}: `{v!r}`" for k, v in per_kind.items())
        others = {k: v for k, v in per_kind.items() if v != spec.default}
        if others:
            return f"`{spec.default!r}` (" + "; ".join(f"{k}: `{v!r}`" for k, v in others.items()) + ")"
    if spec.default is None:
        return "unset"
    return f"`{spec.default!r}`"


def config_page() -> str:
    """The Configuration reference: one table per TOML table, a row per key."""
    from app import config

    kinds = config.kind_defaults()
    lines = ["# Configuration keys", "",
             "Generated from the config schema (`app/config_schema.py` and the keys each geometry kind, material law,",
             "loading and stability criterion declares). Every key is optional; `--set KEY=VALUE` (CLI) or",
             "`load_config(path, {KEY: VALUE})` (Python) overrides any of them. A value outside its range stops",
             "with one line naming the key and the allowed range (exit code 2). How the keys work together:",
             "[Configuration](../../configuration.md).", ""]
    current = None
    for name, spec in schema_keys():
        table = name.split(".")[0] if not name.startswith("material.film.") else "material.film"
        if table != current:
            current = table
            lines += ["", f"## `[{table}]`", "", "| key | type | default | allowed | unit | meaning |",
                      "|---|---|---|---|---|---|"]
        allowed = spec.allowed or ("true or false" if spec.type is bool else "")
        lines.append(f"| `{name}` | {spec.type.__name__} | {_cell(_default(name, spec, kinds))} | {_cell(allowed)} "
                     f"| {_cell(spec.unit)} | {_cell(spec.doc)} |")
    return "\n".join(lines) + "\n"


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _helps(parser: argparse.ArgumentParser) -> dict[str, str]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return {a.dest: a.help or "" for a in action._choices_actions}
    return {}


def cli_page() -> str:
    """The command-line reference: every command's purpose and its ``--help`` text."""
    from app.cli.parser import parser

    p = parser()
    helps = _helps(p)
    lines = ["# Command line", "",
             "Generated from the argument parser (`app/cli/parser.py`). `hydrobuckle COMMAND --help` prints",
             "the same text. Exit codes: 0 success; 1 a solver failure (summary.json says `failed`, everything",
             "computed is kept); 2 bad input (one line naming the key and the allowed range, no result",
             "directory), or a result file that cannot be written; 130 / 143 interrupted by SIGINT / SIGTERM",
             "(summary.json says `interrupted`; `run --resume` continues).", "",
             "| command | what it does |", "|---|---|"]
    subs = _subcommands(p)
    lines += [f"| [`{name}`](#hydrobuckle-{name}) | {_cell(helps.get(name, ''))} |" for name in subs]
    for name, sub in subs.items():
        sub.prog = f"hydrobuckle {name}"
        # a fixed width: the page must not depend on the terminal it was built in ($COLUMNS)
        sub.formatter_class = lambda prog: argparse.HelpFormatter(prog, width=100)
        lines += ["", f"(hydrobuckle-{name})=", f"## `hydrobuckle {name}`", "", helps.get(name, "") + ".", "",
                  "```text", sub.format_help().rstrip(), "```"]
    return "\n".join(lines) + "\n"


def write(outdir: Path = GENERATED) -> list[Path]:
    """Write the generated pages; only files whose text changed are rewritten (Sphinx then rebuilds only
    what changed)."""
    outdir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in (("config.md", config_page()), ("cli.md", cli_page())):
        path = outdir / name
        if not path.is_file() or path.read_text() != text:
            path.write_text(text)
        written.append(path)
    return written


def _on_builder_inited(app) -> None:
    write()


def setup(app):
    app.connect("builder-inited", _on_builder_inited)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
