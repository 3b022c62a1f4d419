"""Provenance of a result, and the one function that writes rkhp's output files (docs/results.md).

Every JSON document and every file rkhp writes (tableaux, trajectories, tables, plot data)
carries a provenance record: rkhp's version, the command line that made it, the seed where one is
used, the date (UTC), and the versions of Python, numpy, scipy, sympy and numba, so that a number
in a paper can be traced back to the run that made it and that run repeated. Library versions are
read from the installed distributions' metadata: nothing heavy is imported to record them.
"""

from __future__ import annotations

import datetime
import json
import platform
import shlex
import sys
from importlib import metadata
from pathlib import Path

from .errors import InputError
from .files import write_atomic

#: the libraries whose versions decide a result's digits, in the record's order
LIBRARIES = ("numpy", "scipy", "sympy", "numba")
#: the record's keys, in order (docs/json.md "provenance")
KEYS = ("rkhp_version", "command", "seed", "date", "python", *LIBRARIES, "platform")


def _version(distribution: str) -> str | None:
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return None


def command_line(argv=None) -> str:
    """The command line of this process as a shell would read it back (``rkhp`` for the console
    script, the script's name for a Python program)."""
    argv = list(sys.argv if argv is None else argv)
    if argv and Path(argv[0]).name in ("rkhp", "__main__.py"):
        argv[0] = "rkhp"
    return shlex.join(argv)


def provenance(command: str | None = None, seed: int | None = None) -> dict:
    """The provenance record (keys :data:`KEYS`): ``command`` defaults to this process's command
    line, ``seed`` is the seed the result depends on (None where none is used)."""
    record = {"rkhp_version": _version("rkhp"), "command": command_line() if command is None else command,
              "seed": None if seed is None else int(seed),
              "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
              "python": platform.python_version()}
    record.update({name: _version(name) for name in LIBRARIES})
    record["platform"] = platform.platform()
    return record


def provenance_line(record: dict, comment: str) -> str:
    """The record as one comment line of a text file (``# provenance: {...}`` for CSV, ``%`` for
    LaTeX): the JSON after ``provenance:`` reads back with json.loads."""
    return f"{comment} provenance: {json.dumps(record, ensure_ascii=False)}"


def read_provenance_line(line: str) -> dict:
    """The record of a :func:`provenance_line` (InputError if the line is not one)."""
    head, sep, body = line.partition("provenance: ")
    if not sep or head.strip() not in ("#", "%"):
        raise InputError(f"not a provenance line: {line[:60]!r}")
    return json.loads(body)


def write_output(path, payload: str | bytes, what: str = "output file", force: bool = False) -> Path:
    """Write ``payload`` (text as UTF-8, or bytes) to ``path``: every file rkhp writes goes through
    here, atomically and never over an existing file (or a symbolic link) unless ``force``
    (rkhp.base.files.write_atomic). InputError naming ``what`` when the file cannot be written."""
    path = Path(path)
    write_atomic(path, payload, what, force)
    return path
