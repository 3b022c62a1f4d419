"""Tables for files and papers: CSV and LaTeX (booktabs) text, each opened by a provenance line
(rkhp.base.provenance; docs/results.md).

A CSV table is a comment line ``# provenance: {...}``, a header row and data rows: read it with
``csv.reader`` after dropping lines that start with ``#`` (pandas: ``comment="#"``; numpy:
``loadtxt(..., comments="#")``). Floats are written by ``repr``, the shortest text that reads
back to the same float64. A LaTeX table is a ``table`` environment with a ``tabular`` ruled by
booktabs (``\\toprule``, ``\\midrule``, ``\\bottomrule``): it needs ``\\usepackage{booktabs}``.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence

from .latex import escape_text
from .provenance import provenance_line


def csv_cell(value) -> str:
    """A value as CSV text: floats by repr (round-trips exactly; nan, inf, -inf as Python writes
    them), None as empty, booleans as true/false, anything else by str."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if hasattr(value, "item"):  # numpy scalars
        return csv_cell(value.item())
    return str(value)


def csv_text(header: Sequence[str], rows, record: dict) -> str:
    """A CSV table: the provenance line of ``record``, the header, then one line per row."""
    buffer = io.StringIO()
    buffer.write(provenance_line(record, "#") + "\n")
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for row in rows:
        writer.writerow([csv_cell(v) for v in row])
    return buffer.getvalue()


#: characters that pdflatex's default text font sets wrongly (OT1: "<" prints as an inverted "!")
_TEXT_SYMBOLS = {"<": "\\textless{}", ">": "\\textgreater{}", "|": "\\textbar{}"}


def latex_cell(text) -> str:
    """A cell's text made safe for LaTeX text mode (rkhp.base.latex.escape_text, and < > |)."""
    return "".join(_TEXT_SYMBOLS.get(ch, ch) for ch in escape_text(str(text)))


def booktabs(header: Sequence[str], rows, caption: str = "", align: str | None = None,
             groups: Sequence[int] = ()) -> str:
    """A LaTeX ``table`` with a booktabs ``tabular``: cells are text (escaped), as the terminal
    shows them; ``align`` is the column spec (default: first column left, the others right);
    ``groups`` are the row indices before which a ``\\midrule`` separates groups of rows."""
    align = align or "l" + "r" * (len(header) - 1)
    if len(align) != len(header):
        raise ValueError(f"column spec {align!r} for {len(header)} columns")
    lines = ["\\begin{table}[htbp]", "\\centering"]
    if caption:
        lines.append(f"\\caption{{{latex_cell(caption)}}}")
    lines += [f"\\begin{{tabular}}{{{align}}}", "\\toprule",
              " & ".join(latex_cell(h) for h in header) + " \\\\", "\\midrule"]
    for i, row in enumerate(rows):
        if i in groups and i > 0:
            lines.append("\\midrule")
        lines.append(" & ".join(latex_cell(c) for c in row) + " \\\\")
    lines += ["\\bottomrule", "\\end{tabular}", "\\end{table}"]
    return "\n".join(lines)


def latex_text(tables: Sequence[str], record: dict) -> str:
    """LaTeX tables (from :func:`booktabs`) after the provenance line of ``record`` and a comment
    naming the package they need."""
    head = [provenance_line(record, "%"), "% needs \\usepackage{booktabs}"]
    return "\n".join(head) + "\n" + "\n\n".join(tables) + "\n"
