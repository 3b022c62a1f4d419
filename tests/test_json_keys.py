"""Every JSON key of the commands is documented in docs/json.md, in one style.

Each command runs once, small, with --format json; every key of every object it prints (except
the keys that are data: numbers such as the orders of `counts`) must be lower snake_case (or `A`,
the Butcher matrix, as in tableau files) and appear quoted in docs/json.md.
"""

from __future__ import annotations

import json
import platform
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from rkhp_cli.main import rkhp as cli

import rkhp
from rkhp.base.provenance import KEYS

DOC = (Path(__file__).resolve().parent.parent / "docs" / "json.md").read_text()

#: commands with a --seed option (default 0)
SEEDED = ("search", "check", "bench", "relations", "modified", "compose")

COMMANDS = [
    ["trees", "--order", "3"],
    ["trees", "--order", "3", "--count"],
    ["conditions", "--order", "5", "--symmetric"],
    ["verify", "paper-two-stage"],
    ["verify", "dop853"],
    ["show", "rk4"],
    ["search", "--stages", "2", "--degenerate", "--restarts", "3"],
    ["systems"],
    ["check", "rigid-body", "--samples", "3"],
    ["integrate", "rigid-body", "--method", "rk4", "--steps", "10"],
    ["converge", "rigid-body", "--method", "paper-two-stage", "--steps", "20", "--refinements", "2"],
    ["bench", "rigid-body", "--method", "euler", "--peers", "scipy:rk45", "--steps", "10,20",
     "--tolerances", "1e-4", "--repeats", "1"],
    ["stress", "lotka-volterra", "--method", "paper-two-stage", "--t-final", "2", "--long-steps", "200",
     "--sweep-coarsest", "8", "--round-off-steps", "8,16,32"],
    ["relations", "--order", "4"],
    ["modified", "--method", "euler", "--order", "3", "--symmetric"],
    ["compose", "euler,euler", "--order", "4", "--symmetric"],
    ["stability", "paper-two-stage,paper-implicit", "--order", "5"],
    ["stability", "euler", "--realisation", "shifted", "--order", "3"],
    ["long-time", "rigid-body", "--steps", "200", "--method", "euler"],
    ["integrate", "pendulum", "--method", "euler", "--steps", "10", "--modified", "3"],
    ["integrate", "rigid-body", "--method", "rk4", "--steps", "10", "--t-eval", "0.5,1.25"],
    ["integrate", "rigid-body", "--method", "tj4", "--explain"],
    ["compile"],
    ["integrate", "rigid-body", "--tol", "1e-6", "--method", "auto"],
    ["poincare", "pendulum", "--section", "x2", "--steps", "200"],
]


def _keys(doc, out: set) -> set:
    if isinstance(doc, dict):
        for k, v in doc.items():
            if not k.isdigit():
                out.add(k)
            _keys(v, out)
    elif isinstance(doc, list):
        for v in doc:
            _keys(v, out)
    return out


@pytest.mark.parametrize("args", COMMANDS, ids=lambda a: " ".join(a[:2]))
def test_every_key_is_documented_in_one_style(args):
    result = CliRunner().invoke(cli, [*args, "--format", "json"])
    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    # the provenance record closes every document (docs/json.md "Provenance")
    record = document["provenance"]
    assert list(document)[-1] == "provenance" and tuple(record) == KEYS
    assert record["command"] == shlex.join(["rkhp", *args, "--format", "json"])
    assert record["rkhp_version"] == rkhp.__version__ and record["numpy"] == np.__version__
    assert record["python"] == platform.python_version() and record["date"].endswith("Z")
    assert record["seed"] == (int(args[args.index("--seed") + 1]) if "--seed" in args else
                              0 if args[0] in SEEDED else None)
    keys = _keys(document, set())
    assert not [k for k in keys if not re.fullmatch(r"[a-z][a-z0-9_]*|A", k)]  # A: as in tableau files
    assert not sorted(k for k in keys if f'"{k}"' not in DOC)
