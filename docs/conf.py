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

# Math: Debian's MathJax (libjs-mathjax, installed by scripts/docs.sh), its TeX -> CommonHTML parts copied
# into the site, so that formulas render offline and on a machine without internet; without it, MathJax
# from its CDN (Sphinx's default).
_MATHJAX = Path("/usr/share/javascript/mathjax")
_MATHJAX_PARTS = ["MathJax.js", "config/TeX-AMS_CHTML.js", "extensions", "jax/input/TeX", "jax/output/CommonHTML",
                  "jax/element", "fonts/HTML-CSS/TeX/woff", "localization/en"]


def _local_mathjax() -> str | None:
    import shutil

    if not (_MATHJAX / "MathJax.js").is_file():
        return None
    static = DOCS / "_build" / "_static_mathjax"
    target = static / "mathjax"
    stamp = target / ".copied-from"
    source = f"{_MATHJAX} {(_MATHJAX / 'MathJax.js').stat().st_mtime}"
    if not stamp.is_file() or stamp.read_text() != source:  # copied whole, or again after an update
        shutil.rmtree(static, ignore_errors=True)
        for part in _MATHJAX_PARTS:
            src, dst = (_MATHJAX / part).resolve(), target / part
            if src.is_dir():
                shutil.copytree(src, dst, dirs_exist_ok=True)
            elif src.is_file():
                dst.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(src, dst)
        stamp.write_text(source)  # last: an interrupted copy has none and is made again
    html_static_path.append(str(static))
    return "mathjax/MathJax.js?config=TeX-AMS_CHTML"


_path = _local_mathjax()
if _path:
    mathjax_path = _path
    # MathJax 2: Sphinx writes math as \( \) and \[ \] in elements of class "math"; MyST's own MathJax 3
    # settings (the "mathjax_ignore" sections) are switched off, they would hide those from MathJax 2
    myst_update_mathjax = False
    mathjax2_config = {"tex2jax": {"inlineMath": [["\\(", "\\)"]], "displayMath": [["\\[", "\\]"]],
                                   "processEscapes": True, "processClass": "math|output_area"},
                       "messageStyle": "none"}
