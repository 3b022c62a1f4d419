"""Sphinx configuration of the rkhp documentation (`make docs`; see docs/index.md, "About these docs")."""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))

project = "rkhp"
author = "the rkhp authors"
copyright = "the rkhp authors"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "mathml",
    "sphinx_click",
    "apigen",
    "docstrings",
    "doccode",
]

# Pages whose blocks run at build time so that the figures they make exist (docs/CONTRIBUTING-DOCS.md).
rkhp_run_at_build = ["tutorials/convergence-study", "implicit"]

source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_generated"]

# Formulas as MathML written at build time (_ext/mathml.py): rendered offline, no MathJax.
html_math_renderer = "mathml"

# MyST: $...$ and $$...$$ math, anchors for headings down to ### (links such as theory.md#4-...).
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

# Every cross-reference must resolve (with -W in `make docs`, a dangling one fails the build).
nitpicky = True

# Objects of other libraries are named in docstrings but not linked (the build is offline: no
# intersphinx inventories); every rkhp name must resolve.
nitpick_ignore_regex = [(r"py:.*", r"(numpy|np|fractions|ast|sympy|mpmath|scipy|numba|pathlib|typing|"
                                   r"collections|concurrent|click|rich)(\..*)?")]

# Docstrings: single backquotes are code; napoleon and escaping in _ext/docstrings.py.
default_role = "code"
autodoc_member_order = "bysource"
autodoc_typehints = "none"

html_theme = "furo"
html_title = "rkhp"
