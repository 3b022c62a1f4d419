"""Input documents: TOML and JSON files read safely, and the typed fields read from them.

A spec file or a tableau file comes from elsewhere, so before any parser sees it (docs/input.md
"Files"):

- it must be a regular file (not a folder, a device or a named pipe) of at most
  :data:`rkhp.base.bounds.MAX_FILE_BYTES`, readable, in UTF-8 (a byte-order mark is allowed) and
  without NUL characters;
- its arrays and tables may nest at most :data:`rkhp.base.bounds.MAX_NESTING` deep (counted by an
  iterative scan, so the recursive parsers never see deeper text);
- JSON objects may not repeat a key, and JSON's non-standard ``NaN``/``Infinity``, numbers that
  overflow a float and integers of more than 30 digits are refused (the field readers refuse such
  integers from TOML too; TOML refuses repeated keys
  itself; its ``nan`` and ``inf`` are refused by :func:`document_number`);
- a number that is not zero but rounds to 0.0 (``1e-400``: below float64's smallest, about
  5e-324) is refused, in TOML and JSON alike, rather than read as 0.

The field readers (:func:`document_number`, :func:`document_integer`, :func:`string`,
:func:`number_list`, :func:`matrix`) refuse type confusion: a boolean is not a number (``t_final = true``), a string is
not a number, a list is not a matrix unless every row has the same length.
"""

from __future__ import annotations

import json
import math
import os
import stat
import tomllib
from pathlib import Path

from . import bounds
from .errors import InputError


def path_exists(path) -> bool:
    """Whether anything (a file, a folder, a link, a broken one too) is at ``path``. A name that
    no file can have (a component longer than the system allows, a NUL character) has nothing at
    it: the question never raises, where `pathlib.Path.exists` raises OSError for such a name, and
    :func:`read_text` says why such a file cannot be read."""
    return os.path.lexists(path)


def is_file(path) -> bool:
    """Whether ``path`` is a regular file, links followed; False for a name that no file can have
    (:func:`path_exists`)."""
    return os.path.isfile(path)


def read_text(path, what: str = "file") -> str:
    """The text of a regular file of at most MAX_FILE_BYTES, decoded as UTF-8 (InputError otherwise)."""
    path = Path(path)
    try:
        info = path.stat()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError(f"{path}: cannot read the {what}: it is a folder")
    if not stat.S_ISREG(info.st_mode):
        raise InputError(f"{path}: not a regular file (a device or a pipe); expected a {what}")
    if info.st_size > bounds.MAX_FILE_BYTES:
        raise InputError(f"{path}: {bounds.size_text(info.st_size)}; a {what} may have at most "
                         f"{bounds.size_text(bounds.MAX_FILE_BYTES)}")
    try:
        with open(path, "rb") as fh:
            data = fh.read(bounds.MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    if len(data) > bounds.MAX_FILE_BYTES:
        raise InputError(f"{path}: a {what} may have at most {bounds.size_text(bounds.MAX_FILE_BYTES)}")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {exc.start}: {data[exc.start:exc.start + 1]!r}); "
                         f"save the {what} as UTF-8") from None
    if "\x00" in text:
        raise InputError(f"{path}: contains NUL characters (a binary file?); expected a {what}")
    return text


def nesting_depth(text: str, toml: bool) -> int:
    """The deepest nesting of [ and { outside strings (and TOML comments), by an iterative scan."""
    depth = deepest = 0
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth -= 1
        elif ch == "#" and toml:
            end = text.find("\n", i)
            i = n if end < 0 else end
            continue
        elif ch == '"' or (ch == "'" and toml):
            i = _string_end(text, i, toml)
            continue
        i += 1
    return deepest


def _string_end(text: str, i: int, toml: bool) -> int:
    """The index after the string starting at text[i] (basic or literal, one or three quotes)."""
    quote = text[i]
    if toml and text.startswith(quote * 3, i):
        end = text.find(quote * 3, i + 3)
        while quote == '"' and end > 0 and _escaped(text, end):
            end = text.find(quote * 3, end + 1)
        return len(text) if end < 0 else end + 3
    j = i + 1
    while j < len(text):
        c = text[j]
        if c == "\\" and quote == '"':
            j += 2
            continue
        if c == quote or (c == "\n" and toml):
            return j + 1
        j += 1
    return len(text)


def _escaped(text: str, j: int) -> bool:
    """Whether text[j] is preceded by an odd number of backslashes."""
    k = j
    while k > 0 and text[k - 1] == "\\":
        k -= 1
    return (j - k) % 2 == 1


def _unique_keys(pairs):
    out = {}
    for key, value in pairs:
        if key in out:
            raise InputError(f"key {key!r} is given twice")
        out[key] = value
    return out


def _json_constant(name):
    raise InputError(f"{name} is not a JSON number (non-finite values are refused)")


def _json_int(text: str) -> int:
    if len(text.lstrip("-")) > bounds.MAX_INT_DIGITS:
        raise InputError(f"integer of {len(text)} digits")
    return int(text)


#: the digits of a number's significand that make it non-zero
NONZERO_DIGITS = frozenset("123456789")


def _float(text: str) -> float:
    """A float literal of a document (TOML's ``inf`` and ``nan`` included, which the field readers
    refuse); InputError for one that is not zero but underflows to 0.0."""
    value = float(text)
    if value == 0.0 and NONZERO_DIGITS & set(text.lower().partition("e")[0]):
        raise InputError(f"number {text[:40]} underflows a float: it is not 0 but below 5e-324")
    return value


def _json_float(text: str) -> float:
    value = _float(text)
    if not math.isfinite(value):
        raise InputError(f"number {text[:40]} overflows a float")
    return value


def parse_document(text: str, where: str, kind: str) -> dict:
    """A TOML ("toml") or JSON ("json") document of keys, parsed safely (module docstring)."""
    depth = nesting_depth(text, kind == "toml")
    if depth > bounds.MAX_NESTING:
        raise InputError(f"{where}: nested {depth} levels deep; at most {bounds.MAX_NESTING}")
    try:
        if kind == "json":
            data = json.loads(text, object_pairs_hook=_unique_keys, parse_constant=_json_constant,
                              parse_int=_json_int, parse_float=_json_float)
        else:
            data = tomllib.loads(text, parse_float=_float)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    except (ValueError, RecursionError) as exc:  # JSONDecodeError and TOMLDecodeError are ValueErrors
        name = "JSON" if kind == "json" else "TOML"
        raise InputError(f"{where}: {name} syntax error: {' '.join(str(exc).split())[:200]}") from None
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a {'JSON object' if kind == 'json' else 'TOML table'} of keys, "
                         f"got {type(data).__name__}")
    if kind == "json":
        _no_surrogates(data, where)
    return data


def _no_surrogates(value, where: str) -> None:
    """JSON's \\ud800 escapes make strings that are not text (they have no UTF-8): refused, in keys and
    values at every level (at most MAX_NESTING, checked before)."""
    items = [*value, *value.values()] if isinstance(value, dict) else value if isinstance(value, list) else ()
    for item in items:
        if isinstance(item, str):
            try:
                item.encode("utf-8")
            except UnicodeEncodeError:
                raise InputError(f"{where}: a string holds a lone surrogate escape (\\ud800 to \\udfff): "
                                 f"not text") from None
        else:
            _no_surrogates(item, where)


def load_document(path, what: str = "file") -> dict:
    """A .json file as JSON, anything else as TOML, read by :func:`read_text` and :func:`parse_document`."""
    path = Path(path)
    kind = "json" if path.suffix.lower() == ".json" else "toml"
    return parse_document(read_text(path, what), str(path), kind)


# ----------------------------------------------------------------------------- typed fields


def _type(value) -> str:
    return {bool: "a boolean", str: "a string", list: "a list", dict: "a table"}.get(
        type(value), type(value).__name__)


def document_number(value, where: str, low: float | None = None, high: float | None = None, *,
           low_open: bool = False) -> float:
    """A finite number (int or float, not a boolean, not text) within the bounds."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where} must be a number, got {_type(value)} {bounds.shown(value)}")
    if isinstance(value, int) and abs(value) >= 10**bounds.MAX_INT_DIGITS:
        raise InputError(f"{where}: an integer of more than {bounds.MAX_INT_DIGITS} digits (TOML and JSON alike)")
    return bounds.number(value, where, low, high, low_open=low_open)


def document_integer(value, where: str, low: int | None = None, high: int | None = None) -> int:
    """An integer (not a boolean, not a float such as 1.0) within the bounds."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{where} must be an integer, got {_type(value)} {bounds.shown(value)}")
    return bounds.integer(value, where, low, high)


def string(value, where: str) -> str:
    if not isinstance(value, str):
        raise InputError(f"{where} must be a string, got {_type(value)} {bounds.shown(value)}")
    return value


def number_list(value, where: str, size: int | None = None, max_size: int | None = None) -> list[float]:
    """A non-empty list of finite numbers (of `size` entries when given)."""
    if not isinstance(value, list) or not value:
        raise InputError(f"{where} must be a non-empty list of numbers, got {_type(value)} {bounds.shown(value)}")
    if max_size is not None and len(value) > max_size:
        raise InputError(f"{where} has {len(value)} entries; at most {max_size}")
    if size is not None and len(value) != size:
        raise InputError(f"{where} must have {size} entries, got {len(value)}")
    return [document_number(v, f"{where}[{i + 1}]") for i, v in enumerate(value)]


def matrix(value, where: str, n: int) -> list[list[float]]:
    """An n x n matrix of finite numbers, as a list of rows."""
    if not isinstance(value, list) or len(value) != n or not all(isinstance(r, list) for r in value):
        shape = f"{len(value)} rows" if isinstance(value, list) else _type(value)
        raise InputError(f"{where} must be {n} x {n} (the size of x0), got {shape}")
    for i, row in enumerate(value):
        if len(row) != n:
            raise InputError(f"{where}: row {i + 1} has {len(row)} entries; expected {n}")
    return [[document_number(v, f"{where}[{i + 1}][{j + 1}]") for j, v in enumerate(row)]
            for i, row in enumerate(value)]
