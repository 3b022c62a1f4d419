"""Sphinx extension: read rkhp's docstrings as the plain text they are written in.

The library's docstrings are plain text with a little reST (``literals``, :func:`roles`) and
Google-style sections (``Attributes:``, ``Args:``). Read as strict reST, the mathematics in them
would be markup: ``|t|`` a substitution, ``a * b`` an emphasis, an indented continuation line a
block quote. This extension keeps their meaning and makes them valid reST:

1. Google-style sections (``Attributes:``, ``Args:``, ``Returns:``, ``Raises:``) become a bold
   heading and a bullet list, one item per entry, the entry's names in code (napoleon is not
   used: it reads ``a, b: text`` or a property's ``text: more`` as types);
2. outside inline literals and roles, ``|`` and ``*`` are escaped;
3. a blank line is put wherever the indentation changes between two lines of text, so that
   continuation lines and lists never end without one;
4. docstrings that are not rkhp's (a property made of ``itemgetter``, a NamedTuple field's
   "Alias for field number 0") are left out.

Single backquotes (```x```) render as inline code (``default_role = "code"`` in conf.py).
"""

from __future__ import annotations

import re

# inline literals, roles with their target, and single-backquoted code: left as they are
PROTECTED = re.compile(r"``.+?``|:[\w:.-]+:`[^`]*`|`[^`]+`")
ENUMERATOR = re.compile(r"^\s*(\(?[0-9a-zA-Z]{1,2}[.)])\s")
FIELD_OR_DIRECTIVE = re.compile(r"^\s*(:[\w ]+:|\.\. )")
SECTION = re.compile(r"^(\s*)(Args|Arguments|Parameters|Attributes|Returns|Raises|Yields):\s*$")
ENTRY = re.compile(r"^([\w., ]+?)(\s*\([^)]*\))?:(\s|$)")


def sections_as_lists(lines: list[str]) -> list[str]:
    """Each Google-style section as a bold heading and a bullet list of its entries."""
    out: list[str] = []
    i = 0
    while i < len(lines):
        match = SECTION.match(lines[i])
        if not match:
            out.append(lines[i])
            i += 1
            continue
        ind = match.group(1)
        body = []
        i += 1
        while i < len(lines) and (not lines[i].strip() or indent(lines[i]) > len(ind)):
            body.append(lines[i])
            i += 1
        while body and not body[-1].strip():
            body.pop()
        entry_indent = min((indent(b) for b in body if b.strip()), default=0)
        out += [f"{ind}**{match.group(2)}**", ""]
        for b in body:
            if not b.strip():
                continue
            text = b.strip()
            if indent(b) == entry_indent:
                head = ENTRY.match(text)
                if head:
                    names = ", ".join(f"``{n.strip()}``" for n in head.group(1).split(","))
                    text = names + (head.group(2) or "") + ":" + text[head.end(1) + len(head.group(2) or "") + 1:]
                out.append(f"{ind}- {text}")
            else:
                out.append(f"{ind}  {text}")
        out.append("")
    return out


def escape_markup(line: str) -> str:
    """``|`` and ``*`` escaped outside protected spans (a leading ``* `` bullet is kept)."""
    out, last = [], 0
    for match in PROTECTED.finditer(line):
        out.append(_escape(line[last:match.start()]))
        out.append(match.group(0))
        last = match.end()
    out.append(_escape(line[last:]))
    text = "".join(out)
    return re.sub(r"^(\s*)\\\* ", r"\1* ", text)


def _escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("*", "\\*")


def indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def separate_blocks(lines: list[str]) -> list[str]:
    """A blank line between two text lines of different indentation, and after an enumerated
    item followed by plain text at its own indentation."""
    out: list[str] = []
    for line in lines:
        if out and out[-1].strip() and line.strip():
            prev = out[-1]
            changed = indent(prev) != indent(line)
            list_end = bool(ENUMERATOR.match(prev)) and not ENUMERATOR.match(line)
            continues_field = FIELD_OR_DIRECTIVE.match(prev) and indent(line) > indent(prev)
            if (changed or list_end) and not prev.rstrip().endswith("::") and not continues_field:
                out.append("")
        out.append(line)
    return out


def foreign(obj) -> bool:
    """Whether a docstring is not rkhp's own: a property built on a C-level getter (itemgetter)
    or a NamedTuple field ("Alias for field number 0")."""
    getter = getattr(obj, "fget", None)
    if getter is not None and not (getattr(getter, "__module__", "") or "").startswith("rkhp"):
        return True
    return type(obj).__name__ == "_tuplegetter"


def process_docstring(app, what, name, obj, options, lines):
    """autodoc-process-docstring: escaping, sections as lists, blank lines between blocks."""
    if foreign(obj):
        lines[:] = []
        return
    escaped = [line if line.lstrip().startswith(".. ") else escape_markup(line) for line in lines]
    lines[:] = separate_blocks(sections_as_lists(escaped))


def setup(app):
    app.connect("autodoc-process-docstring", process_docstring)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
