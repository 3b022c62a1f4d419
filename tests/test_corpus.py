"""The independent hostile corpus: several hundred cases, written as data.

tests/data/hostile_corpus.jsonl holds one case per line, written without reference to the code
under test or to tests/test_hostile.py (a second, independent check of the same promise):

- ``name``, ``class`` (what kind of hostility), ``command``, ``args`` (the argv after ``rkhp``);
- ``files``: what the case's empty folder holds before the run: a text, ``{"hex": ...}`` (bytes),
  ``{"symlink": TARGET}``, ``{"fifo": true}`` or ``{"dir": true}``;
- ``status`` (default 2), ``seconds`` (the wall bound, default :data:`SECONDS`), ``env``,
  ``slow`` (left to `make test-all`), ``creates`` (files a successful case writes).

Texts and arguments may hold ``{{REPEAT N PIECE}}``: N copies of PIECE (a 10^6-character
expression is one line of the data file, not a megabyte).

Every case runs as ``rkhp ARGS`` in a process forked from tests/forkserver.py (one warm server per
test process; pytest-xdist spreads the cases) in a folder of its own, and must end with its exit
status, exactly one non-empty line on stderr starting ``rkhp:`` (for a non-zero status), no
traceback, within its wall bound; the files it found must be there unchanged (a symbolic link's
target included), and nothing else may appear (no temporary ``.*.tmp``, no PWNED).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import stat
from collections import Counter
from pathlib import Path

import pytest
from fork_client import ENV, ForkServer

CORPUS = Path(__file__).with_name("data") / "hostile_corpus.jsonl"
#: wall bound of a case (a refusal is meant to be immediate; the bound allows a loaded machine)
SECONDS = 10.0
#: limits of the case's process: CPU seconds and address space
CPU_SECONDS = 20
ADDRESS_SPACE = 2 << 30
COMMANDS = ("trees", "conditions", "verify", "tables", "show", "search", "systems", "check", "integrate", "compose",
            "modified", "stability", "relations", "converge", "bench", "long-time", "stress", "compile")
CLASSES = ("bad-number", "size", "expression", "malformed", "file", "format", "unknown", "step", "contradictory",
           "numerical")

REPEAT = re.compile(r"\{\{REPEAT (\d+) (.*?)\}\}", re.S)


def expand(text: str) -> str:
    return REPEAT.sub(lambda m: m.group(2) * int(m.group(1)), text)


def _load() -> list[dict]:
    with CORPUS.open(encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]


CASES = _load()


def _param(case: dict):
    marks = [pytest.mark.slow] if case.get("slow") else []
    return pytest.param(case, id=case["name"], marks=marks)


# --------------------------------------------------------------------------- the folder


def _materialise(folder: Path, files: dict) -> None:
    for name, content in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, str):
            path.write_bytes(expand(content).encode("utf-8"))
        elif "hex" in content:
            path.write_bytes(bytes.fromhex(content["hex"]))
        elif "symlink" in content:
            path.symlink_to(content["symlink"])
        elif "fifo" in content:
            os.mkfifo(path)
        elif "dir" in content:
            path.mkdir()
        else:
            raise ValueError(f"unknown file kind {content}")


def _snapshot(folder: Path) -> dict:
    """Every entry under the folder: its kind and content (a link: its target, not followed)."""
    entries = {}
    for root, dirs, names in os.walk(folder):
        for name in dirs + names:
            path = Path(root, name)
            mode = path.lstat().st_mode
            if stat.S_ISLNK(mode):
                entries[str(path.relative_to(folder))] = ("link", os.readlink(path))
            elif stat.S_ISREG(mode):
                entries[str(path.relative_to(folder))] = ("file", hashlib.sha256(path.read_bytes()).hexdigest())
            else:
                entries[str(path.relative_to(folder))] = ("other", stat.S_IFMT(mode))
    return entries


# --------------------------------------------------------------------------- the server


@pytest.fixture(scope="module")
def server():
    forks = ForkServer()
    yield forks
    forks.close()


# --------------------------------------------------------------------------- the tests


def test_the_corpus_covers_every_command_and_class():
    assert len(CASES) >= 300
    assert len({c["name"] for c in CASES}) == len(CASES)
    commands = Counter(c["command"] for c in CASES)
    classes = Counter(c["class"] for c in CASES)
    assert all(commands[name] for name in COMMANDS), set(COMMANDS) - set(commands)
    assert set(classes) == set(CLASSES)
    assert all(case.get("status", 2) in (0, 1, 2) for case in CASES)


@pytest.mark.parametrize("case", [_param(c) for c in CASES])
def test_case(case, server, tmp_path):
    folder = tmp_path / "case"
    folder.mkdir()
    _materialise(folder, case.get("files", {}))
    before = _snapshot(folder)
    out, err = tmp_path / "stdout", tmp_path / "stderr"
    out.touch()
    err.touch()
    bound = case.get("seconds", SECONDS)
    answer = server.run({"args": [expand(a) for a in case["args"]], "cwd": str(folder),
                         "env": {**os.environ, **ENV, **case.get("env", {})}, "stdout": str(out), "stderr": str(err),
                         "address_space": ADDRESS_SPACE, "cpu_seconds": CPU_SECONDS, "wall_seconds": 3 * bound})
    stderr = err.read_bytes().decode("utf-8", "replace")
    status = case.get("status", 2)
    assert answer["status"] != "timeout", f"no end within {3 * bound} s"
    assert "Traceback" not in stderr, stderr[-3000:]
    assert answer["status"] == status, (answer["status"], stderr[-3000:])
    if status:
        line, _, rest = stderr.partition("\n")
        assert rest == "" and stderr.endswith("\n") and line.startswith("rkhp: ") and line[6:].strip(), stderr[-3000:]
    assert answer["wall"] <= bound, f"{answer['wall']:.1f} s > {bound} s"
    after = _snapshot(folder)
    created = set(after) - set(before)
    assert created == set(case.get("creates", ())), f"created {sorted(created)}"
    assert {k: v for k, v in after.items() if k in before} == before, "a file found was changed or removed"
