"""The [output] keys: what a run writes (app.io.output.OutputSettings). Imports nothing of app but the schema:
app.config, below io/, reads this table (the one exception the layers contract names, pyproject.toml)."""

from __future__ import annotations

from app.schema import Key, ge, key

OUTPUT: dict[str, Key] = {
    "fields": key(bool, True, None, "write fields.xdmf"),
    "every": key(int, 1, ge(1), "write fields every n accepted steps"),
    "plot": key(bool, True, None, "write history.png"),
    "checkpoint_every": key(int, 10, ge(0), "write checkpoint.npz every n accepted steps (and when "
                            "interrupted), for 'run --resume'; 0 = off"),
}
