"""LaTeX documents that compile on their own with pdflatex (public packages only).

The paper draws trees with a private ``\\forest`` macro and sets tables with a private ``C`` column
type. Here a tree is drawn with TikZ (package ``tikz``, in every TeX distribution) through the
macros ``\\rkhptree`` and ``\\rkhpnode`` defined in the preamble (root at the bottom, as in the
paper; the layout is computed here), and ``C`` is defined from the ``array`` package, so that
:func:`standalone` output compiles as it is; to paste the body into a paper, copy the preamble
lines as well.
"""

from __future__ import annotations

_TREE_PREAMBLE = r"""\usepackage{tikz}
\newcommand{\rkhptree}[1]{\tikz[baseline={([yshift=-.6ex]current bounding box.center)},
  x=5pt, y=7pt, line cap=round]{#1\path (current bounding box.south) ++(0,-4pt)
  (current bounding box.north) ++(0,4pt);}}
\newcommand{\rkhpnode}[1]{\fill #1 circle (1.4pt);}"""

_BASE_PREAMBLE = r"""\documentclass{article}
\usepackage[margin=2cm]{geometry}
\usepackage{amsmath}"""

_TABLE_PREAMBLE = r"""\usepackage{array}
\usepackage{longtable}
\newcolumntype{C}{>{$}c<{$}}"""

_SPECIALS = {"\\": r"\textbackslash{}", "{": r"\{", "}": r"\}", "$": r"\$", "&": r"\&", "#": r"\#",
             "^": r"\^{}", "_": r"\_", "%": r"\%", "~": r"\~{}"}


def escape_text(text: str) -> str:
    """Plain text made safe for LaTeX text mode."""
    return "".join(_SPECIALS.get(ch, ch) for ch in text)


def tree_layout(tree) -> tuple[list[tuple[float, int]], list[tuple[int, int]]]:
    """Node positions (x, depth) and edges (parent, child) of a tree drawn root at the bottom:
    leaves at consecutive x, each parent centred below its children."""
    nodes: list[tuple[float, int]] = []
    edges: list[tuple[int, int]] = []
    next_leaf = [0]

    def place(t, depth: int) -> int:
        index = len(nodes)
        nodes.append((0.0, depth))
        kids = [place(c, depth + 1) for c in t.children]
        if kids:
            x = (nodes[kids[0]][0] + nodes[kids[-1]][0]) / 2
        else:
            x = float(next_leaf[0])
            next_leaf[0] += 1
        nodes[index] = (x, depth)
        edges.extend((index, k) for k in kids)
        return index

    place(tree, 0)
    root_x = nodes[0][0]
    return [(x - root_x, d) for x, d in nodes], edges


def tree_latex(tree) -> str:
    """``\\rkhptree{...}``: the tree in TikZ, for :func:`standalone`'s ``\\rkhptree`` macro."""
    nodes, edges = tree_layout(tree)

    def node_at(k: int) -> str:
        x, d = nodes[k]
        return f"({x:g},{d})"

    draw = "".join(f"\\draw {node_at(p)}--{node_at(c)};" for p, c in edges)
    dots = "".join(f"\\rkhpnode{{{node_at(k)}}}" for k in range(len(nodes)))
    return "\\rkhptree{" + draw + dots + "}"


def longtable(header, rows) -> str:
    """A longtable in the layout of the paper's Table 1 (math cells, a rule between orders)."""
    cols = "|".join("C" for _ in header)
    lines = [f"\\begin{{longtable}}{{{cols}}}", " & ".join(header) + "\\\\\\hline"]
    previous = None
    for row in rows:
        row = tuple(str(c) for c in row)
        if previous is not None and row[0] != previous:
            lines.append("\\hline")
        cells = row if row[0] != previous else ("",) + row[1:]
        lines.append(" & ".join(cells) + "\\\\")
        previous = row[0]
    lines.append("\\end{longtable}")
    return "\n".join(lines)


def standalone(body: str, title: str = "", tables: bool = False, trees: bool = False) -> str:
    """A complete document around ``body``, with the ``C`` column type and longtable when
    ``tables``, and the tree macros when ``trees``."""
    preamble = "\n".join([_BASE_PREAMBLE] + [_TABLE_PREAMBLE] * tables + [_TREE_PREAMBLE] * trees)
    head = f"\\noindent {title}\n\n" if title else ""
    return f"{preamble}\n\\begin{{document}}\n{head}{body}\n\\end{{document}}"
