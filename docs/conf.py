"""Sphinx configuration of hydrobuckle's documentation (built by ``bash scripts/docs.sh``)."""

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS.parent))

from app.version import __version__  # noqa: E402

project = "hydrobuckle"
author = "the hydrobuckle developers"
copyright = "2026, the hydrobuckle developers"
release = version = __version__

extensions = ["myst_nb", "sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinx.ext.mathjax", "hbreference"]

# Markdown pages (MyST) and the literate demos (jupytext percent scripts, executed when the docs build)
source_suffix = {".md": "myst-nb", ".py": "myst-nb"}
nb_custom_formats = {".py": ["jupytext.reads", {"fmt": "py:percent"}]}
exclude_patterns = ["_build", "_ext", "conf.py", "theory/*.py", "bench/*", "Thumbs.db", ".DS_Store"]
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
suppress_warnings = []

# HYDROBUCKLE_DOCS_EXECUTE=0 skips running the demos (a quick look at the text); scripts/docs.sh runs them
nb_execution_mode = "force" if os.environ.get("HYDROBUCKLE_DOCS_EXECUTE", "1") != "0" else "off"
nb_execution_timeout = 900
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True
nb_execution_in_temp = True  # the demos write their results into a temporary directory, not into docs/

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": False}

html_theme = "furo"
html_title = f"hydrobuckle {release}"
html_static_path = []
