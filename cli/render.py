"""Tables that never cut a number or a name: fit the console by wrapping at spaces only, else fold.

A rich table squeezed below its content's width folds cells mid-word (``-0.103471`` / ``829727``) or
cuts them with an ellipsis. :func:`print_table` fixes every column's width so that no word of a cell
or header is split; when even the longest words do not fit side by side, each row is printed as a
block instead (its first cell on one line, then ``header: value`` pairs), see docs/show.md.
"""

from __future__ import annotations

from rich.cells import cell_len
from rich.text import Text


def _plain(cell) -> str:
    if isinstance(cell, Text):
        return cell.plain
    if isinstance(cell, str):
        return Text.from_markup(cell).plain
    return str(cell)


def _longest_word(text: str) -> int:
    return max((cell_len(w) for line in text.splitlines() for w in line.split()), default=0)


def _longest_line(text: str) -> int:
    return max((cell_len(line) for line in text.splitlines()), default=0)


def _column_ranges(table) -> list[tuple[int, int]]:
    """(narrowest width without splitting a word, natural width) of each column's content."""
    ranges = []
    for column in table.columns:
        texts = [_plain(c) for c in column.cells]
        header = _plain(column.header)
        natural = max([_longest_line(t) for t in texts] + [_longest_line(header)], default=1)
        if column.no_wrap:
            narrow = natural
        else:
            narrow = max([_longest_word(t) for t in texts] + [_longest_word(header)], default=1)
        ranges.append((max(narrow, 1), max(natural, 1)))
    return ranges


def _width(console, table) -> int:
    from rich.measure import Measurement

    return Measurement.get(console, console.options.update_width(1 << 16), table).maximum


def fit(console, table) -> bool:
    """Fix the table's column widths so that it fits the console with every word whole.

    Columns give up width from the one with the most room above its longest word. Returns False
    (the table unchanged) when the longest words alone are too wide.
    """
    ranges = _column_ranges(table)
    widths = [natural for _, natural in ranges]
    saved = [(c.width, c.overflow) for c in table.columns]
    for column, w in zip(table.columns, widths, strict=True):
        column.width = w
    excess = _width(console, table) - console.width
    slack = [w - narrow for w, (narrow, _) in zip(widths, ranges, strict=True)]
    if excess > sum(slack):
        for column, (w, overflow) in zip(table.columns, saved, strict=True):
            column.width, column.overflow = w, overflow
        return False
    while excess > 0:
        k = max(range(len(widths)), key=lambda i: slack[i])
        widths[k] -= 1
        slack[k] -= 1
        excess -= 1
    for column, w in zip(table.columns, widths, strict=True):
        column.width = w
        column.overflow = "fold"  # never reached: each column is at least its longest word
    return True


def folded(table) -> list[Text]:
    """The rows of a table as blocks: the first cell, then ``header: value`` of the others."""
    headers = [_plain(c.header) for c in table.columns]
    columns = [[c for c in col.cells] for col in table.columns]
    blocks = []
    for r in range(table.row_count):
        cells = [_plain(col[r]) if r < len(col) else "" for col in columns]
        block = Text(cells[0], style="bold")
        for header, value in zip(headers[1:], cells[1:], strict=True):
            if value.strip():
                block.append(f"\n  {header}: " if header else "\n  ")
                block.append(" ".join(value.split()))
        blocks.append(block)
    return blocks


def compact_table(title=None, **kw):
    """A rich table without vertical rules (so that more fits in 80 columns), title on the left."""
    from rich import box
    from rich.table import Table

    return Table(title=title, title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False,
                 collapse_padding=True, **kw)


def print_table(console, table) -> None:
    """Print a rich table without cutting a word: fitted to the console, else folded by rows."""
    if fit(console, table):
        console.print(table)
        return
    if table.title:
        console.print(table.title)
    for block in folded(table):
        console.print(block)
    if table.caption:
        console.print(table.caption)


def print_array(out, tab, fmt, heading: str) -> None:
    """The Butcher array as a block when it fits the console, else its non-zero entries row by
    row, packed into lines (a number is never split across lines)."""
    from rich.text import Text

    from rkhp.tableaux.tableau import butcher_text, is_zero

    block = butcher_text(tab, fmt)
    out.print()
    if max(len(line) for line in block.splitlines()) <= out.width:
        out.print(heading)
        out.print(Text(block))
        return
    out.print(f"{heading}; non-zero entries row by row (the array is wider than the output)")
    s = tab.stages
    for i in range(s):
        items = [f"c[{i + 1}] = {fmt(tab.c[i])}"] + [
            f"a[{i + 1},{j + 1}] = {fmt(x)}" for j, x in enumerate(tab.A[i]) if not is_zero(x)]
        for line in pack(items, out.width):
            out.print(Text(line))
    for line in pack([f"b[{j + 1}] = {fmt(x)}" for j, x in enumerate(tab.b) if not is_zero(x)],
                     out.width):
        out.print(Text(line))


def pack(items: list[str], width: int, gap: str = "   ", indent: str = "  ") -> list[str]:
    """Items joined by ``gap`` into lines of at most ``width`` (an item longer than a line stands
    alone); lines after the first are indented."""
    lines: list[str] = []
    current = ""
    for item in items:
        candidate = item if not current else current + gap + item
        if current and len(candidate) > width:
            lines.append(current)
            current = indent + item
        else:
            current = candidate
    if current:
        lines.append(current)
    return lines


def plan_line(planned) -> str:
    """The line --tol prints before the run: the pilot's estimate and the steps chosen."""
    c = planned.choice
    pilot = c.pilot
    auto = ""
    if planned.candidates:
        auto = "method auto: " + ", ".join(
            f"{k.method} {k.choice.steps} steps ~{k.choice.predicted_seconds:.2g} s" if k.choice else
            f"{k.method} left out" for k in planned.candidates) + "; "
    return (f"{auto}tol {c.tolerance:g}: {c.method} (order {c.order}), pilot {pilot.steps[0]}..{pilot.finest_steps} "
            f"steps, estimated error {pilot.estimate:.2g} at {pilot.finest_steps} steps"
            f"{' (round-off)' if pilot.round_off else ''}; chose {c.steps} steps of h = {c.h:.6g} "
            f"(predicted error {c.predicted_error:.2g}, about {c.predicted_seconds:.2g} s)")
