"""Tableau files: the built-in registry (``tables/*.toml``), TOML/JSON files, 60-digit text files.

Schema (TOML, or the same keys in JSON; README "Tableau files"):

    name = "rk4"                      # optional in a user file (default: the file name)
    aliases = ["classical"]           # optional
    reference = "Kutta (1901) ..."    # optional
    order = 4                         # optional: the claimed (general) order
    degenerate_order = 4              # optional: the claimed order over T_0
    symmetric_order = 4               # optional: the claimed order in the symmetric class
    notes = "..."                     # optional
    [provenance]                      # optional: how the file was made (docs/json.md), not read
    A = [["0", "0"], ["1/2", "0"]]    # s rows of s entries
    b = ["0", "1"]
    c = ["0", "1/2"]                  # optional; compared with the row sums of A

Entries are numbers or strings (see :func:`rkhp.tableaux.tableau.parse_entry`). The 60-digit text files
(Feagin's format: sections ``c[k]``, ``b[k]``, ``bhat[k]``, ``A[k,j]``, 0-based indices, rows not
listed are zero) load as well.
"""

from __future__ import annotations

import difflib
import json
import re
from functools import lru_cache
from importlib.resources import files
from pathlib import Path

import tomli_w

from ..base.bounds import MAX_CLAIMED_ORDER, MAX_STAGES
from ..base.documents import is_file, parse_document, path_exists, read_text
from ..base.errors import InputError
from ..base.provenance import write_output
from .tableau import Tableau, entry_text, parse_entry

_KEYS = ("name", "aliases", "reference", "order", "degenerate_order", "symmetric_order", "notes", "A",
         "b", "c", "provenance")
_FILE_SUFFIXES = (".toml", ".json", ".txt")


# ----------------------------------------------------------------------------- built-ins


def _tables_dir():
    return files("rkhp.tables")


@lru_cache(maxsize=1)
def _registry() -> dict[str, tuple[str, tuple[str, ...]]]:
    """name -> (file name, aliases) for every built-in table, read once."""
    out = {}
    for entry in sorted(_tables_dir().iterdir(), key=lambda p: p.name):
        if not entry.name.endswith(".toml"):
            continue
        text = entry.read_text(encoding="utf-8")
        # only the one-line `name` and `aliases` keys are needed here: parsing them alone spares
        # reading every coefficient of every table (60-digit files) on each start-up
        head = "\n".join(line for line in text.splitlines() if line.startswith(("name ", "name=", "aliases")))
        where = f"tables/{entry.name}"
        try:
            data = parse_document(head, where, "toml")
        except InputError:  # `name` or `aliases` written over several lines: the whole file
            data = parse_document(text, where, "toml")
        name = data.get("name", entry.name[:-5])
        out[name] = (entry.name, tuple(data.get("aliases", ())))
    return out


def builtin_names() -> list[str]:
    """Names of the built-in tableaux (the files in ``tables/``), in file-name order."""
    return list(_registry())


@lru_cache(maxsize=1)
def _alias_map() -> dict[str, str]:
    """lower-case name or alias -> name, for every built-in table (read-only, built once)."""
    out = {}
    for name, (_, aliases) in _registry().items():
        out[name.lower()] = name
        for alias in aliases:
            out[alias.lower()] = name
    return out


@lru_cache(maxsize=64)
def _load_builtin(name: str) -> Tableau:
    filename = _registry()[name][0]
    text = (_tables_dir() / filename).read_text(encoding="utf-8")
    where = f"tables/{filename}"
    return tableau_from_mapping(parse_document(text, where, "toml"), where, filename[:-5])


def load_tableau(name_or_path) -> Tableau:
    """A built-in tableau by name or alias (case-insensitive), or a .toml/.json/.txt file.

    Raises InputError naming the file and the problem, or suggesting close built-in names.
    """
    if isinstance(name_or_path, Tableau):
        return name_or_path
    text = str(name_or_path)
    if not text.strip():  # Path("") is the current folder
        raise InputError("empty tableau name; see `rkhp tables` for the built-in names")
    path = Path(text)
    aliases = _alias_map()
    if text.lower() in aliases and not is_file(path):
        return _load_builtin(aliases[text.lower()])
    if path.suffix.lower() in _FILE_SUFFIXES or path_exists(path) or "/" in text:
        return load_file(path)
    close = difflib.get_close_matches(text.lower(), list(aliases), n=3, cutoff=0.6)
    hint = (" (did you mean " + ", ".join(sorted({aliases[c] for c in close})) + "?)"
            if close else "; see `rkhp tables` for the built-in names")
    raise InputError(f"unknown tableau {text!r}{hint}")


def load_file(path) -> Tableau:
    """Read a tableau file (.toml, .json or a 60-digit .txt)."""
    path = Path(path)
    text = read_text(path, "tableau file")
    suffix = path.suffix.lower()
    if suffix == ".txt":
        return parse_digits_file(text, str(path), path.stem)
    data = parse_document(text, str(path), "json" if suffix == ".json" else "toml")
    return tableau_from_mapping(data, str(path), path.stem)


def tableau_from_mapping(data, where: str, default_name: str) -> Tableau:
    """A tableau from the schema's keys (a parsed TOML or JSON document)."""
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a table of keys {', '.join(_KEYS)}")
    unknown = sorted(set(data) - set(_KEYS))
    if unknown:
        raise InputError(f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(_KEYS)})")
    for key in ("A", "b"):
        if key not in data:
            raise InputError(f"{where}: missing key {key!r}")
    A = data["A"]
    if not isinstance(A, list) or not all(isinstance(r, list) for r in A):
        raise InputError(f"{where}: A must be a list of rows (lists of entries)")
    if max(len(A), *(len(r) for r in A), len(data["b"]) if isinstance(data["b"], list) else 0) > MAX_STAGES:
        raise InputError(f"{where}: more than {MAX_STAGES} stages")
    for key in ("order", "degenerate_order", "symmetric_order"):
        value = data.get(key, 1)
        if type(value) is not int or not 1 <= value <= MAX_CLAIMED_ORDER:
            raise InputError(f"{where}: claimed {key} must be a positive integer (at most {MAX_CLAIMED_ORDER}), "
                             f"got {value!r}"[:300])
    for key in ("b", "c", "aliases"):
        if key in data and not isinstance(data[key], list):
            raise InputError(f"{where}: {key} must be a list")
    for key in ("name", "reference", "notes"):
        if key in data and not isinstance(data[key], str):
            raise InputError(f"{where}: {key} must be a string")
    if "provenance" in data and not isinstance(data["provenance"], dict):
        raise InputError(f"{where}: provenance must be a table")
    if not all(isinstance(a, str) for a in data.get("aliases", [])):
        raise InputError(f"{where}: aliases must be strings")
    name = data.get("name", default_name)
    A_ = tuple(tuple(parse_entry(x, f"{where}: A[{i + 1}][{j + 1}]") for j, x in enumerate(row))
               for i, row in enumerate(A))
    b_ = tuple(parse_entry(x, f"{where}: b[{i + 1}]") for i, x in enumerate(data["b"]))
    c_ = (tuple(parse_entry(x, f"{where}: c[{i + 1}]") for i, x in enumerate(data["c"]))
          if "c" in data else None)
    return Tableau(name=name, A=A_, b=b_, c_given=c_, aliases=tuple(data.get("aliases", ())),
                   reference=data.get("reference", ""), notes=data.get("notes", ""),
                   claimed_order=data.get("order"),
                   claimed_degenerate_order=data.get("degenerate_order"),
                   claimed_symmetric_order=data.get("symmetric_order"), source=where)


# ----------------------------------------------------------------------------- 60-digit files

_SECTION = re.compile(r"^\s*k\s+(j\s+)?(c|b|bhat|A)\[k(,j)?\]\s*$")


def parse_digits_file(text: str, where: str, name: str) -> Tableau:
    """Feagin's 60-digit format: ``c[k]``, ``b[k]``, optional ``bhat[k]``, then ``A[k,j]``.

    Indices are 0-based, rows of A not listed are zero; ``bhat`` (embedded weights) is not kept.
    Lines outside the sections (titles, remarks) are ignored.
    """
    sections: dict[str, dict] = {}
    current = None
    for lineno, line in enumerate(text.splitlines(), 1):
        m = _SECTION.match(line)
        if m:
            current = m.group(2)
            sections[current] = {}
            continue
        fields = line.split()
        if current is None or not fields:
            continue
        width = 3 if current == "A" else 2
        if not (fields[0].isascii() and fields[0].isdigit()):
            current = None  # a remark after the data
            continue
        if len(fields) != width or not all(f.isascii() and f.isdigit() for f in fields[:-1]):
            raise InputError(f"{where}: line {lineno}: expected {width} fields in the {current} "
                             f"section, got {line.strip()!r}")
        if any(len(f) > 4 for f in fields[:-1]):
            raise InputError(f"{where}: line {lineno}: index beyond the {MAX_STAGES} stages allowed")
        index = tuple(int(f) for f in fields[:-1])
        sections[current][index] = parse_entry(fields[-1], f"{where}: line {lineno}")
    for key in ("b", "A"):
        if key not in sections:
            raise InputError(f"{where}: no {key} section (expected Feagin's 60-digit format)")
    s = max((k for (k,) in sections["b"]), default=-1) + 1
    if not 1 <= s <= MAX_STAGES:
        raise InputError(f"{where}: {s} stages; from 1 to {MAX_STAGES}")
    A = [[parse_entry(0)] * s for _ in range(s)]
    for (k, j), value in sections["A"].items():
        if k >= s or j >= s:
            raise InputError(f"{where}: A[{k},{j}] outside the {s} stages given by b")
        A[k][j] = value
    b = [sections["b"].get((k,), parse_entry(0)) for k in range(s)]
    c = [sections["c"].get((k,), parse_entry(0)) for k in range(s)] if "c" in sections else None
    return Tableau(name=name, A=tuple(map(tuple, A)), b=tuple(b),
                   c_given=None if c is None else tuple(c), source=where)


# ----------------------------------------------------------------------------- writing


def tableau_mapping(tableau: Tableau) -> dict:
    """The schema's keys for a tableau, entries as strings that read back exactly."""
    data: dict = {"name": tableau.name}
    if tableau.aliases:
        data["aliases"] = list(tableau.aliases)
    if tableau.reference:
        data["reference"] = tableau.reference
    if tableau.claimed_order is not None:
        data["order"] = tableau.claimed_order
    if tableau.claimed_degenerate_order is not None:
        data["degenerate_order"] = tableau.claimed_degenerate_order
    if tableau.claimed_symmetric_order is not None:
        data["symmetric_order"] = tableau.claimed_symmetric_order
    if tableau.notes:
        data["notes"] = tableau.notes
    data["A"] = [[entry_text(x) for x in row] for row in tableau.A]
    data["b"] = [entry_text(x) for x in tableau.b]
    if tableau.c_given is not None:
        data["c"] = [entry_text(x) for x in tableau.c_given]
    return data


def save_tableau(tableau: Tableau, path, provenance: dict | None = None, force: bool = False) -> None:
    """Write a tableau as TOML or JSON (by the file's extension), with its ``provenance`` record
    (rkhp.base.provenance) when given: a table that the reader accepts and does not use (TOML has
    no null: a null value is left out there). Written atomically; an existing file (or a symbolic
    link) is replaced only with ``force`` (`rkhp.base.files`)."""
    path = Path(path)
    data = tableau_mapping(tableau)
    suffix = path.suffix.lower()
    if provenance is not None:
        data["provenance"] = (provenance if suffix == ".json"
                              else {k: v for k, v in provenance.items() if v is not None})
    if suffix == ".json":
        text = json.dumps(data, indent=2, ensure_ascii=False) + "\n"
    elif suffix == ".toml":
        text = tomli_w.dumps(data, multiline_strings=False)
    else:
        raise InputError(f"{path}: cannot write a tableau as {suffix or 'a file without extension'}"
                         " (use .toml or .json)")
    write_output(path, text, "tableau file", force)
