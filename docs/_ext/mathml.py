"""Formulas rendered when the site is built: LaTeX to MathML (latex2mathml), so that every page
shows its formulas offline, with no script and nothing fetched (browsers render MathML natively).

Registered as Sphinx's HTML math renderer ``mathml`` (conf.py: ``html_math_renderer``): an inline
formula becomes ``<math>``, a display formula ``<div class="math"><math display="block">``. A
formula that latex2mathml cannot read fails the build (warnings are errors in ``make docs``).
"""

from __future__ import annotations

from docutils import nodes
from latex2mathml.converter import convert
from sphinx.util import logging

LOGGER = logging.getLogger(__name__)


def mathml(latex: str, display: bool, node) -> str:
    """The MathML of a formula; a warning naming it (an error in the build) if it cannot be read
    (an empty one, which MyST makes of the ``$$`` of a display formula already given, is nothing)."""
    if not latex.strip():
        return ""
    try:
        return convert(latex.strip(), display="block" if display else "inline")
    except Exception as exc:  # noqa: BLE001 - any failure of the converter is the formula's
        LOGGER.warning("formula not rendered (%s): %s", type(exc).__name__, latex[:80], location=node)
        return f"<code>{latex}</code>"


def visit_math(self, node):
    self.body.append(mathml(node.astext(), False, node))
    raise nodes.SkipNode


def visit_math_block(self, node):
    self.body.append(self.starttag(node, "div", CLASS="math notranslate nohighlight"))
    self.body.append(mathml(node.astext(), True, node))
    self.body.append("</div>\n")
    raise nodes.SkipNode


def setup(app):
    app.add_html_math_renderer("mathml", (visit_math, None), (visit_math_block, None))
    return {"parallel_read_safe": True, "parallel_write_safe": True}
