"""Hostile input through the real command line: a corpus of named cases.

Every case runs `rkhp ARGS` in a process of its own, forked from a server that has imported the
command line once (tests/forkserver.py: the process is what `python -m rkhp ARGS` would be, less
its start-up), in its own empty folder holding only the files the case writes, under resource
limits (address space 1 GiB, 10 s of CPU, 10 s of wall time). Each must end with the exit status
it names (2 for bad input, 1 for a detected numerical failure), exactly one line on stderr, no
traceback, and must create nothing: the payloads would create a file named PWNED in the folder (or
in an absolute path inside it) if anything executed them.

Each case is a test (pytest-xdist spreads them over the cores; one fork server per test process).
Only a few cases get as far as the compiled engine (numerical failures, exit status 1); the server's
fixture first fills numba's cache for them (WARM_UP).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import pytest
from fork_client import ENV, ForkServer

#: limits the child runs under (the acceptance's: 10 s, 1 GiB); CPU time is what a case costs
#: (the wall time of a loaded machine is longer), the wall guard catches a process that blocks
CPU_SECONDS = 10
ADDRESS_SPACE = 1 << 30
WALL_GUARD = 60.0


class Case(NamedTuple):
    """A hostile input: the command's arguments, the files it reads, the exit status expected.

    Arguments and file texts may contain ``{d}``: the case's folder (absolute path). A file text
    may be a function returning it: a large text is then built by the test that writes it, not by
    every test process collecting the corpus.
    """

    name: str
    args: tuple[str, ...]
    files: dict = {}
    status: int = 2
    env: dict = {}


#: a file's text, or a function returning it (built by the test that writes the file)
Text = str | bytes | Callable[[], str]


class Link(str):
    """A file that is a symbolic link to this target (or, for "fifo", a named pipe nobody writes)."""


# --------------------------------------------------------------------------- building blocks

RIGID = {
    "family": "lie-poisson",
    "structure_constants": [[1, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]],
    "hamiltonian": "x1^2/4 + x2^2/2 + 3*x3^2/4",
    "x0": [0.4536, 0.0, 0.8912],
    "t_final": 10.0,
    "casimirs": ["x1^2 + x2^2 + x3^2"],
}
PENDULUM = {"family": "constant", "poisson": [[0, 1], [-1, 0]], "hamiltonian": "x2^2/2 - cos(x1)",
            "x0": [1.5, 0.0], "t_final": 0.1}
LOTKA = {"family": "log-canonical", "lambda": [[0, 1, 2], [-1, 0, 1], [-2, -1, 0]],
         "hamiltonian": "x1 + x2 + x3 - log(x1) - log(x2) - log(x3)", "x0": [0.5, 1.0, 2.0]}

RK4 = {"A": [["0", "0", "0", "0"], ["1/2", "0", "0", "0"], ["0", "1/2", "0", "0"], ["0", "0", "1", "0"]],
       "b": ["1/6", "1/3", "1/3", "1/6"]}


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)


def toml(doc: dict, **changes) -> str:
    """A TOML file of `doc` with `changes` (None deletes a key); values as TOML literals."""
    merged = {**doc, **changes}
    return "".join(f"{k} = {_toml_value(v)}\n" for k, v in merged.items() if v is not None)


def jsondoc(doc: dict, **changes) -> str:
    merged = {k: v for k, v in {**doc, **changes}.items() if v is not None}
    return json.dumps(merged)


def spec(name: str, text: Text, command: str = "check", suffix: str = ".toml", status: int = 2) -> Case:
    """A spec-file case: `rkhp check FILE --samples 1` (or integrate, converge...)."""
    file = "s" + suffix
    args = {"check": ("check", file, "--samples", "1"),
            "integrate": ("integrate", file, "--method", "rk4", "--steps", "1")}[command]
    return Case(name, args, {file: text}, status)


def tableau(name: str, text: Text, suffix: str = ".toml", status: int = 2) -> Case:
    return Case(name, ("verify", "t" + suffix), {"t" + suffix: text}, status)


#: code that would create PWNED if it ran, in every disguise the expression reader must refuse
PAYLOADS = {
    "import": "__import__('os').system('touch PWNED') or x1",
    "import-abs": "__import__('os').system('touch {d}/PWNED') or x1",
    "attribute": "x1.__class__.__mro__[-1].__subclasses__()",
    "builtins": "__builtins__.__import__('os').system('touch PWNED')",
    "lambda": "(lambda: __import__('os').system('touch PWNED'))() or x1",
    "listcomp": "[__import__('os').system('touch PWNED') for _ in (1,)][0] or x1",
    "genexp": "sum(__import__('os').system('touch PWNED') for _ in (1,)) + x1",
    "setcomp": "{__import__('os').system('touch PWNED') for _ in (1,)}",
    "dictcomp": "{k: __import__('os').system('touch PWNED') for k in (1,)}",
    "exec": "exec(\"__import__('os').system('touch PWNED')\")",
    "eval": "eval(\"__import__('os').system('touch PWNED')\") + x1",
    "open": "open('PWNED', 'w') and x1",
    "getattr": "getattr(__import__('os'), 'system')('touch PWNED')",
    "string": "\"__import__('os').system('touch PWNED')\"",
    "fstring": "f\"{__import__('os').system('touch PWNED')}\"",
    "walrus": "(y := __import__('os').system('touch PWNED')) or x1",
    "ifexp": "x1 if __import__('os').system('touch PWNED') else x1",
    "subprocess": "__import__('subprocess').run(['touch', 'PWNED']) or x1",
    "statement": "x1; __import__('os').system('touch PWNED')",
    "newline": "x1\n__import__('os').system('touch PWNED')",
    "dunder-func": "exp.__globals__['__builtins__']['__import__']('os').system('touch PWNED')",
    "sympy-attr": "pi.evalf.__globals__",
    "sympify": "sympify(\"__import__('os').system('touch PWNED')\")",
    "fullwidth": "__\uff49mport__('os').system('touch PWNED')",
    "call-kw": "exp(x=__import__('os').system('touch PWNED'))",
    "subscript": "x1[__import__('os').system('touch PWNED')]",
}


def _payload_cases() -> list[Case]:
    cases = []
    for key, p in PAYLOADS.items():
        cases.append(spec(f"payload-hamiltonian-{key}", toml(RIGID, hamiltonian=p)))
    for key in ("import", "lambda", "listcomp", "dunder-func", "string"):
        p = PAYLOADS[key]
        cases.append(spec(f"payload-hamiltonian-json-{key}", jsondoc(RIGID, hamiltonian=p), suffix=".json"))
        cases.append(spec(f"payload-casimir-{key}", toml(RIGID, casimirs=[p])))
        cases.append(spec(f"payload-poisson-{key}", toml(PENDULUM, poisson=[[0, p], [-1, 0]])))
        cases.append(spec(f"payload-lambda-{key}", toml(LOTKA, **{"lambda": [[0, p, 2], [-1, 0, 1], [-2, -1, 0]]})))
        cases.append(spec(f"payload-structure-{key}",
                          toml(RIGID, structure_constants=[[1, 2, 3, p], [2, 3, 1, -1], [3, 1, 2, -1]])))
        cases.append(tableau(f"payload-tableau-A-{key}", toml(RK4, A=[["0", "0"], [p, "0"]], b=["0", "1"])))
        cases.append(tableau(f"payload-tableau-b-json-{key}", jsondoc(RK4, b=[p, "1/3", "1/3", "1/6"]), ".json"))
    cases.append(tableau("payload-tableau-txt", "k b[k]\n0 __import__('os').system('touch PWNED')\n"
                         "k j A[k,j]\n", ".txt"))
    cases.append(tableau("payload-tableau-name", toml(RK4, name="[link=file:///etc]x[/link]\x1b[2J"), status=0))
    cases.append(Case("payload-method-name", ("integrate", "pendulum", "--method",
                                              "__import__('os').system('touch PWNED')", "--steps", "1")))
    cases.append(Case("payload-x0", ("integrate", "pendulum", "--method", "rk4", "--steps", "1", "--x0",
                                     "__import__('os').system('touch PWNED'),1")))
    cases.append(Case("payload-precision", ("verify", "rk4", "--precision", "__import__('os').system('touch PWNED')")))
    cases.append(Case("payload-system-name", ("check", "__import__('os').system('touch PWNED')")))
    return cases


def _expression_cases() -> list[Case]:
    """Expressions that are too big, too deep or not finite, in Hamiltonians and tableau entries."""
    exprs = {
        "tower": "10^10^10",
        "tower-var": "x1^10^10",
        "big-exponent": "x1^1000000",
        "huge-literal": "1e999999999",
        "tiny-literal": "1e-999999999 + x1",
        "long-int": "9" * 5000 + " + x1",
        "long-text": "+".join(["x1"] * 20_000),
        "deep-parens": "(" * 5000 + "x1" + ")" * 5000,
        "deep-unary": "-" * 5000 + "x1",
        "deep-calls": "exp(" * 200 + "x1" + ")" * 200,
        "nested-exp": "exp(exp(exp(exp(exp(1000))))) + x1",
        "factorial-digits": "(2^256)^(2^8)",
        "div-zero": "1/0 + x1",
        "log-zero": "log(0) + x1",
        "nan-name": "nan",
        "inf-name": "inf * x1",
        "nul": "x1\x00",
        "empty": "",
        "blank": "   ",
        "bool": "True",
        "complex": "1j * x1",
        "unknown-var": "x4 + x1",
        "unknown-func": "gamma(x1)",
        "bad-syntax": "x1 +* x2",
        "comparison": "x1 < x2",
        "is-literal": "x1 is 1",
        "decimal-warning": "1or x1",
        "escape-warning": "'\\d' and x1",
        "bitwise": "x1 ^ 2 | x2",
        "floordiv": "x1 // 2",
        "modulo": "x1 % 2",
        "two-args": "exp(x1, x2)",
        "bytes": "b'x1'",
        "ellipsis": "...",
        "none": "None",
    }
    cases = [spec(f"expr-hamiltonian-{k}", toml(RIGID, hamiltonian=v)) for k, v in exprs.items()]
    for k in ("tower", "huge-literal", "tiny-literal", "long-int", "deep-parens", "nested-exp", "div-zero",
              "bitwise", "empty"):
        v = exprs[k].replace("x1", "1")
        cases.append(tableau(f"expr-tableau-{k}", toml(RK4, b=[v, "1/3", "1/3", "1/6"])))
    cases += [
        tableau("entry-huge-rational", toml(RK4, b=["1" * 5000 + "/3", "1/3", "1/3", "1/6"])),
        tableau("entry-huge-decimal-exponent", toml(RK4, b=["1e999999999", "1/3", "1/3", "1/6"])),
        tableau("entry-tiny-decimal-exponent", toml(RK4, b=["1e-999999999", "1/3", "1/3", "1/6"])),
        tableau("entry-long-decimal", toml(RK4, b=["0." + "1" * 100_000, "1/3", "1/3", "1/6"])),
        tableau("entry-nan-string", toml(RK4, b=["nan", "1/3", "1/3", "1/6"])),
        tableau("entry-transcendental", toml(RK4, b=["exp(1)", "1/3", "1/3", "1/6"])),
        tableau("entry-complex-root", toml(RK4, b=["sqrt(-1)", "1/3", "1/3", "1/6"])),
        tableau("entry-radical-tower", toml(RK4, b=["sqrt(" * 60 + "2" + ")" * 60, "1/3", "1/3", "1/6"])),
        Case("entry-many-radicals-exact", ("verify", "t.toml", "--precision", "exact"),
             {"t.toml": toml(RK4, b=["1/(" + "+".join(f"sqrt({p})" for p in (2, 3, 5, 7, 11, 13, 17, 19, 23, 29)) + ")",
                                     "1/3", "1/3", "1/6"])}),
    ]
    return cases


def _spec_cases() -> list[Case]:
    """Spec files: type confusion, missing or extra keys, non-finite values, broken semantics."""
    return [
        spec("t-final-true", toml(RIGID, t_final=True)),
        spec("t-final-string", toml(RIGID, t_final="10")),
        spec("t-final-zero", toml(RIGID, t_final=0)),
        spec("t-final-negative", toml(RIGID, t_final=-1.0)),
        spec("t-final-nan", toml(RIGID, t_final=float("nan")).replace("nan", "nan")),
        spec("t-final-inf", "t_final = inf\n" + toml(RIGID, t_final=None)),
        spec("t-final-huge-int", toml(RIGID, t_final=10**400).replace(str(10**400), "9" * 400)),
        spec("t-final-json-bool", jsondoc(RIGID, t_final=True), suffix=".json"),
        spec("t-final-json-huge", jsondoc(RIGID, t_final=None)[:-1] + ', "t_final": 1e999}', suffix=".json"),
        spec("x0-bools", toml(RIGID, x0=[True, False, True])),
        spec("x0-strings", toml(RIGID, x0=["0.4", "0", "0.9"])),
        spec("x0-nested", toml(RIGID, x0=[[0.4], [0.0], [0.9]])),
        spec("x0-empty", toml(RIGID, x0=[])),
        spec("x0-nan", "x0 = [nan, 0.0, 0.9]\n" + toml(RIGID, x0=None)),
        spec("x0-inf", "x0 = [inf, 0.0, 0.9]\n" + toml(RIGID, x0=None)),
        spec("x0-huge-int", toml(RIGID, x0=[1, 0, 0]).replace("[1,", "[" + "9" * 400 + ",")),
        spec("x0-wrong-size", toml(RIGID, x0=[0.4, 0.0])),
        spec("x0-too-many", toml(RIGID, x0=[0.1] * 100_000)),
        spec("x0-json-null", jsondoc(RIGID, x0=[None, 0.0, 0.9]), suffix=".json"),
        spec("x0-json-nan", jsondoc(RIGID, x0=None)[:-1] + ', "x0": [NaN, 0, 0.9]}', suffix=".json"),
        spec("x0-json-infinity", jsondoc(RIGID, x0=None)[:-1] + ', "x0": [Infinity, 0, 0.9]}', suffix=".json"),
        spec("x0-string", toml(RIGID, x0="0.4, 0, 0.9")),
        spec("poisson-jacobi-overflow", toml(RIGID, family="general", structure_constants=None,
                                             poisson=[["0", "1e200", "0"], ["-1e200", "0", "1e200*exp(x2)"],
                                                      ["0", "-1e200*exp(x2)", "0"]])),
        spec("casimir-not-a-casimir-overflow",
             toml(RIGID, structure_constants=[[1, 2, 3, -1e200], [2, 3, 1, -1e200], [3, 1, 2, -1e200]],
                  casimirs=["1e200*exp(x1)"])),
        spec("lambda-overflow-at-x0", toml(LOTKA, x0=[1.0, 2.0, 3.0],
                                           **{"lambda": [[0, 1e308, 1], [-1e308, 0, 1], [-1, -1, 0]]}),
             "integrate"),
        spec("x0-json-underflow", jsondoc(RIGID, x0=None)[:-1] + ', "x0": [0.4, 1e-400, 0.9]}', suffix=".json"),
        spec("x0-toml-underflow", "x0 = [0.4, 1e-400, 0.9]\n" + toml(RIGID, x0=None)),
        spec("x0-outside-domain", toml(LOTKA, x0=[-0.5, 1.0, 2.0])),
        spec("h-nonfinite-at-x0", toml(PENDULUM, hamiltonian="log(x1) + x2^2", x0=[-1.0, 0.0])),
        spec("h-zero-division-at-x0", toml(PENDULUM, hamiltonian="1/x1 + x2^2", x0=[0.0, 0.5])),
        spec("h-sqrt-negative-at-x0", toml(PENDULUM, hamiltonian="sqrt(x1) + x2^2", x0=[-4.0, 0.5])),
        spec("h-overflow-at-x0", toml(PENDULUM, hamiltonian="exp(x1) + x2^2", x0=[1000.0, 0.5])),
        spec("casimir-nonfinite-at-x0", toml(PENDULUM, casimirs=["log(x1 - 2)"])),
        spec("casimir-not-a-casimir", toml(RIGID, casimirs=["x1 + x2"])),
        spec("casimir-energy-not-casimir", toml(RIGID, casimirs=["x1^2/4 + x2^2/2 + 3*x3^2/4"])),
        spec("casimir-lv-wrong", toml(LOTKA, casimirs=["log(x1) + log(x2)"])),
        spec("casimir-pendulum-wrong", toml(PENDULUM, casimirs=["x1"])),
        spec("casimirs-not-list", toml(RIGID, casimirs="x1^2 + x2^2 + x3^2")),
        spec("casimirs-number", toml(RIGID, casimirs=[1])),
        spec("hamiltonian-number", toml(RIGID, hamiltonian=3)),
        spec("hamiltonian-bool", toml(RIGID, hamiltonian=True)),
        spec("hamiltonian-list", toml(RIGID, hamiltonian=["x1"])),
        spec("hamiltonian-missing", toml(RIGID, hamiltonian=None)),
        spec("family-unknown", toml(RIGID, family="symplectic")),
        spec("family-missing", toml(RIGID, family=None)),
        spec("family-list", toml(RIGID, family=["lie-poisson"])),
        spec("name-number", toml(RIGID, name=3)),
        spec("name-bool", toml(RIGID, name=True)),
        spec("unknown-key", toml(RIGID, colour="blue")),
        spec("wrong-family-key", toml(RIGID, poisson=[[0, 1], [-1, 0]])),
        spec("structure-bool-index", toml(RIGID, structure_constants=[[True, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]])),
        spec("structure-bool-value", toml(RIGID, structure_constants=[[1, 2, 3, True], [2, 3, 1, -1], [3, 1, 2, -1]])),
        spec("structure-float-index", toml(RIGID, structure_constants=[[1.0, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]])),
        spec("structure-index-zero", toml(RIGID, structure_constants=[[0, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]])),
        spec("structure-huge-index", toml(RIGID, structure_constants=[[10**18, 2, 3, -1]])),
        spec("structure-nan", "structure_constants = [[1, 2, 3, nan]]\n" + toml(RIGID, structure_constants=None)),
        spec("structure-not-jacobi", toml(RIGID, structure_constants=[[1, 2, 3, 1], [2, 3, 1, 1], [3, 1, 2, 1],
                                                                      [1, 2, 1, 1]])),
        spec("structure-empty", toml(RIGID, structure_constants=[])),
        spec("structure-short-entry", toml(RIGID, structure_constants=[[1, 2, 3]])),
        spec("poisson-bools", toml(PENDULUM, poisson=[[False, True], [True, False]])),
        spec("poisson-not-antisymmetric", toml(PENDULUM, poisson=[[0, 1], [1, 0]])),
        spec("poisson-ragged", toml(PENDULUM, poisson=[[0, 1], [-1]])),
        spec("poisson-wrong-size", toml(PENDULUM, poisson=[[0, 1, 0], [-1, 0, 0], [0, 0, 0]])),
        spec("poisson-huge-int", toml(PENDULUM, poisson=[[0, 1], [-1, 0]]).replace("[0, 1]", "[0, " + "9" * 400 + "]")),
        spec("poisson-inf", "poisson = [[0, inf], [-inf, 0]]\n" + toml(PENDULUM, poisson=None)),
        spec("lambda-strings", toml(LOTKA, **{"lambda": [["0", "1", "2"], ["-1", "0", "1"], ["-2", "-1", "0"]]})),
        spec("lambda-not-antisymmetric", toml(LOTKA, **{"lambda": [[0, 1, 2], [1, 0, 1], [-2, -1, 0]]})),
        spec("dimension-huge", lambda: toml(PENDULUM, poisson=[[0] * 3000] * 3000, x0=[0.0] * 3000, hamiltonian="x1")),
    ]


def _file_cases() -> list[Case]:
    """Files that are missing, unreadable, folders, binary, huge, mis-encoded, duplicated, deep."""
    deep_json = "[" * 100_000 + "]" * 100_000
    deep_toml_array = "x0 = " + "[" * 100_000 + "]" * 100_000 + "\n"
    deep_toml_table = "x0 = " + "{a = " * 5_000 + "1" + "}" * 5_000 + "\n"
    return [
        Case("spec-missing", ("check", "missing.toml")),
        Case("spec-folder", ("check", "folder.toml"), {"folder.toml/inside": "x"}),
        Case("spec-binary", ("check", "s.toml"), {"s.toml": bytes(range(256)) * 4}),
        Case("spec-utf16", ("check", "s.toml"), {"s.toml": toml(RIGID).encode("utf-16")}),
        Case("spec-latin1", ("check", "s.toml"), {"s.toml": ('name = "caf\xe9"\n' + toml(RIGID)).encode("latin-1")}),
        Case("spec-huge", ("check", "s.toml"), {"s.toml": lambda: "# " + "x" * (64 << 20) + "\n"}),
        Case("spec-devzero", ("check", "s.toml"), {"s.toml": Link("/dev/zero")}),
        Case("spec-fifo", ("check", "s.json"), {"s.json": Link("fifo")}),
        Case("spec-duplicate-json-keys", ("check", "s.json"),
             {"s.json": jsondoc(RIGID)[:-1] + ', "hamiltonian": "x1"}'}),
        Case("spec-duplicate-toml-keys", ("check", "s.toml"), {"s.toml": toml(RIGID) + 'hamiltonian = "x1"\n'}),
        Case("spec-deep-json", ("check", "s.json"), {"s.json": deep_json}),
        Case("spec-deep-json-value", ("check", "s.json"),
             {"s.json": jsondoc(RIGID, x0=None)[:-1] + ', "x0": ' + deep_json + "}"}),
        Case("spec-deep-toml-array", ("check", "s.toml"), {"s.toml": deep_toml_array}),
        Case("spec-deep-toml-table", ("check", "s.toml"), {"s.toml": deep_toml_table}),
        Case("spec-json-array", ("check", "s.json"), {"s.json": "[1, 2, 3]"}),
        Case("spec-json-string", ("check", "s.json"), {"s.json": '"rigid"'}),
        Case("spec-json-empty", ("check", "s.json"), {"s.json": ""}),
        Case("spec-toml-syntax", ("check", "s.toml"), {"s.toml": "x0 = [1, 2\n"}),
        Case("spec-json-huge-int", ("check", "s.json"), {"s.json": '{"x0": [' + "9" * 5000 + "]}"}),
        Case("spec-bom", ("check", "s.json"), {"s.json": "\ufeff" + jsondoc(RIGID, casimirs=["x1"])}),
        Case("spec-unreadable", ("check", "s.toml"), {"s.toml": Link("/proc/self/mem")}),
        Case("spec-dangling-link", ("check", "s.toml"), {"s.toml": Link("nowhere.toml")}),
        Case("spec-link-loop", ("check", "s.toml"), {"s.toml": Link("s.toml")}),
        Case("tableau-missing", ("verify", "missing.toml")),
        Case("tableau-folder", ("verify", "folder.json"), {"folder.json/inside": "x"}),
        Case("tableau-binary", ("verify", "t.toml"), {"t.toml": b"\x00\xff\xfe" * 1000}),
        Case("tableau-binary-txt", ("verify", "t.txt"), {"t.txt": b"\x89PNG\r\n\x1a\n" + bytes(500)}),
        Case("tableau-huge", ("verify", "t.json"), {"t.json": lambda: " " * (64 << 20) + "{}"}),
        Case("tableau-utf16", ("verify", "t.toml"), {"t.toml": toml(RK4).encode("utf-16")}),
        Case("tableau-duplicate-json-keys", ("verify", "t.json"), {"t.json": jsondoc(RK4)[:-1] + ', "b": ["1"]}'}),
        Case("tableau-deep-json", ("verify", "t.json"), {"t.json": '{"A": ' + deep_json + ', "b": []}'}),
        Case("tableau-deep-toml", ("verify", "t.toml"), {"t.toml": "A = " + "[" * 100_000 + "]" * 100_000}),
        Case("tableau-unreadable", ("verify", "t.toml"), {"t.toml": Link("/proc/self/mem")}),
        Case("tableau-fifo", ("verify", "t.toml"), {"t.toml": Link("fifo")}),
        tableau("tableau-bool-entry", toml(RK4, b=[True, "1/3", "1/3", "1/6"])),
        tableau("tableau-json-null-entry", jsondoc(RK4, b=[None, "1/3", "1/3", "1/6"]), ".json"),
        tableau("tableau-json-nan-entry", jsondoc(RK4)[:-1] + ', "c": [NaN, 0.5, 0.5, 1]}', ".json"),
        tableau("tableau-json-inf-entry", jsondoc(RK4, b=None)[:-1] + ', "b": [1e999, 0, 0, 0]}', ".json"),
        tableau("tableau-json-huge-int", jsondoc(RK4, b=None)[:-1] + ', "b": [' + "9" * 5000 + ', 0, 0, 0]}', ".json"),
        tableau("tableau-toml-inf-entry", "b = [inf, 0, 0, 0]\n" + toml(RK4, b=None)),
        tableau("tableau-order-bool", toml(RK4, order=True)),
        tableau("tableau-order-float", toml(RK4, order=4.0)),
        tableau("tableau-order-huge", toml(RK4, order=10**18)),
        tableau("tableau-ragged", toml(RK4, A=[["0"], ["1/2", "0"]], b=["0", "1"])),
        tableau("tableau-empty", toml(RK4, A=[], b=[])),
        tableau("tableau-A-string", toml(RK4, A="0")),
        tableau("tableau-dict-entry", jsondoc(RK4, b=[{"x": 1}, 0, 0, 0]), ".json"),
        tableau("tableau-huge-stages", lambda: toml({"A": [["0"] * 3000] * 3000, "b": ["0"] * 3000})),
        tableau("tableau-txt-huge-index", "k b[k]\n999999999999 1\nk j A[k,j]\n0 0 0\n", ".txt"),
        tableau("tableau-txt-no-sections", "hello\n", ".txt"),
        tableau("tableau-unknown-suffix", "A = []", ".yaml"),
    ]


def _option_cases() -> list[Case]:
    """Command options out of range, of the wrong type, unbounded, or writing where they cannot."""
    quick = ("--method", "rk4")
    return [
        Case("trees-order-negative", ("trees", "--order", "-1")),
        Case("trees-order-zero", ("trees", "--order", "0")),
        Case("trees-order-huge", ("trees", "--order", "99")),
        Case("trees-order-bignum", ("trees", "--order", "9" * 5000)),
        Case("trees-order-float", ("trees", "--order", "3.5")),
        Case("trees-count-huge", ("trees", "--order", "100000", "--count")),
        Case("conditions-order-huge", ("conditions", "--order", "40")),
        Case("conditions-both-classes", ("conditions", "--order", "3", "--degenerate", "--symmetric")),
        Case("verify-max-order-negative", ("verify", "rk4", "--max-order", "-1")),
        Case("verify-max-order-huge", ("verify", "rk4", "--max-order", "1000")),
        Case("verify-precision-zero", ("verify", "rk4", "--precision", "0")),
        Case("verify-precision-huge", ("verify", "rk4", "--precision", "999999999")),
        Case("verify-precision-bignum", ("verify", "rk4", "--precision", "9" * 5000)),
        Case("verify-precision-nan", ("verify", "rk4", "--precision", "nan")),
        Case("verify-show-negative", ("verify", "rk4", "--show", "-1")),
        Case("verify-unknown-tableau", ("verify", "rk5000")),
        Case("tables-precision-bad", ("tables", "--precision", "-3")),
        Case("search-stages-zero", ("search", "--stages", "0")),
        Case("search-stages-huge", ("search", "--stages", "1000")),
        Case("search-order-huge", ("search", "--stages", "2", "--order", "100")),
        Case("search-restarts-negative", ("search", "--stages", "2", "--restarts", "-5")),
        Case("search-restarts-huge", ("search", "--stages", "2", "--restarts", "10000000000000")),
        Case("search-seed-negative", ("search", "--stages", "2", "--order", "2", "--seed", "-1")),
        Case("search-seed-huge", ("search", "--stages", "2", "--order", "2", "--seed", "9" * 100)),
        Case("search-time-limit-zero", ("search", "--stages", "2", "--time-limit", "0")),
        Case("search-time-limit-nan", ("search", "--stages", "2", "--time-limit", "nan")),
        Case("search-time-limit-inf", ("search", "--stages", "2", "--time-limit", "inf")),
        Case("search-time-limit-negative", ("search", "--stages", "2", "--time-limit", "-1")),
        Case("search-workers-zero", ("search", "--stages", "2", "--workers", "0")),
        Case("search-workers-huge", ("search", "--stages", "2", "--workers", "100000")),
        Case("search-digits-low", ("search", "--stages", "2", "--digits", "3")),
        Case("search-digits-huge", ("search", "--stages", "2", "--digits", "100000000")),
        Case("search-save-missing-folder", ("search", "--stages", "2", "--order", "2", "--save", "nowhere/t.toml")),
        Case("search-save-folder", ("search", "--stages", "2", "--order", "2", "--save", "out.toml"),
             {"out.toml/inside": "x"}),
        Case("search-save-suffix", ("search", "--stages", "2", "--order", "2", "--save", "t.exe")),
        Case("search-save-under-file", ("search", "--stages", "2", "--order", "2", "--save", "f/t.toml"),
             {"f": "x"}),
        Case("search-save-device", ("search", "--stages", "2", "--order", "2", "--save", "t.toml"),
             {"t.toml": Link("/dev/full")}),
        Case("check-samples-zero", ("check", "pendulum", "--samples", "0")),
        Case("check-samples-huge", ("check", "pendulum", "--samples", "1000000000000")),
        Case("check-seed-negative", ("check", "pendulum", "--seed", "-1")),
        Case("check-seed-huge", ("check", "pendulum", "--seed", "1" + "0" * 40)),
        Case("check-realisation-unknown", ("check", "pendulum", "--realisation", "bogus")),
        Case("integrate-steps-zero", ("integrate", "pendulum", *quick, "--steps", "0")),
        Case("integrate-steps-negative", ("integrate", "pendulum", *quick, "--steps", "-10")),
        Case("integrate-steps-memory", ("integrate", "pendulum", *quick, "--steps", "1000000000000")),
        Case("integrate-steps-bignum", ("integrate", "pendulum", *quick, "--steps", "9" * 5000)),
        Case("compile-jobs-zero", ("compile", "--jobs", "0")),
        Case("compile-jobs-bignum", ("compile", "--jobs", "9" * 5000)),
        Case("compile-jobs-text", ("compile", "--jobs", "all")),
        Case("integrate-h-zero", ("integrate", "pendulum", *quick, "--h", "0")),
        Case("integrate-h-against-t", ("integrate", "pendulum", *quick, "--h", "-0.1", "--t-final", "1")),
        Case("integrate-h-nan", ("integrate", "pendulum", *quick, "--h", "nan")),
        Case("integrate-h-inf", ("integrate", "pendulum", *quick, "--h", "inf")),
        Case("integrate-h-tiny", ("integrate", "pendulum", *quick, "--h", "1e-300")),
        Case("integrate-h-not-dividing", ("integrate", "pendulum", *quick, "--h", "0.25", "--t-final", "0.1")),
        Case("integrate-h-not-dividing-2", ("integrate", "pendulum", *quick, "--h", "0.3", "--t-final", "1")),
        Case("integrate-h-and-steps", ("integrate", "pendulum", *quick, "--h", "0.1", "--steps", "10")),
        Case("integrate-t-final-zero", ("integrate", "pendulum", *quick, "--steps", "1", "--t-final", "0")),
        Case("integrate-t-final-nan", ("integrate", "pendulum", *quick, "--steps", "1", "--t-final", "nan")),
        Case("integrate-t-final-huge", ("integrate", "pendulum", *quick, "--h", "1e-300", "--t-final", "1e300")),
        Case("integrate-x0-nan", ("integrate", "pendulum", *quick, "--steps", "1", "--x0", "nan,0")),
        Case("integrate-x0-inf", ("integrate", "pendulum", *quick, "--steps", "1", "--x0", "1e999,0")),
        Case("integrate-x0-size", ("integrate", "pendulum", *quick, "--steps", "1", "--x0", "1,2,3")),
        Case("integrate-x0-empty", ("integrate", "pendulum", *quick, "--steps", "1", "--x0", "")),
        Case("integrate-x0-empty-item", ("integrate", "pendulum", *quick, "--steps", "1", "--x0", "1,,2")),
        Case("integrate-x0-trailing-comma", ("integrate", "pendulum", *quick, "--steps", "1", "--x0", "1,2,")),
        Case("integrate-x0-h-overflow", ("integrate", "pendulum", *quick, "--steps", "1", "--x0", "0,1e308")),
        Case("integrate-x0-casimir-overflow",
             ("integrate", "rigid-body", *quick, "--steps", "1", "--x0", "1e154,1e154,1e154")),
        Case("integrate-x0-domain", ("integrate", "lotka-volterra", *quick, "--steps", "1", "--x0", "-1,1,1")),
        Case("integrate-x0-h-nonfinite", ("integrate", "s.toml", *quick, "--steps", "1", "--x0", "-3,0"),
             {"s.toml": toml(PENDULUM, hamiltonian="log(x1 + 2) + x2^2")}),
        Case("integrate-thp-zero", ("integrate", "pendulum", "--method", "thp0", "--steps", "1")),
        Case("integrate-thp-huge", ("integrate", "pendulum", "--method", "thp99999999999", "--steps", "1")),
        Case("integrate-implicit-h-too-large", ("integrate", "pendulum", "--method", "gauss2", "--h", "5"),
             status=1),
        Case("relations-order-zero", ("relations", "--order", "0")),
        Case("relations-order-huge", ("relations", "--order", "50")),
        Case("relations-regenerate-huge", ("relations", "--order", "12", "--regenerate")),
        Case("relations-seed-negative", ("relations", "--order", "3", "--regenerate", "--seed", "-4")),
        Case("relations-output-folder", ("relations", "--order", "3", "--regenerate", "--output", "out.json"),
             {"out.json/inside": "x"}),
        Case("relations-output-missing", ("relations", "--order", "3", "--regenerate", "--output", "no/out.json")),
        Case("converge-refinements-huge", ("converge", "pendulum", *quick, "--refinements", "1000000000")),
        Case("converge-refinements-negative", ("converge", "pendulum", *quick, "--refinements", "-1")),
        Case("converge-steps-zero", ("converge", "pendulum", *quick, "--steps", "0,10,20")),
        Case("converge-steps-text", ("converge", "pendulum", *quick, "--steps", "a,b")),
        Case("converge-steps-empty-item", ("converge", "pendulum", *quick, "--steps", "10,,20,40")),
        Case("converge-x0-h-overflow", ("converge", "pendulum", *quick, "--x0", "0,1e308", "--steps", "10")),
        Case("converge-steps-memory", ("converge", "pendulum", *quick, "--steps", "10,20,100000000000")),
        Case("converge-t-final-nan", ("converge", "pendulum", *quick, "--t-final", "nan")),
        Case("converge-t-final-huge", ("converge", "pendulum", *quick, "--t-final", "1e308")),
        Case("converge-duplicate-methods", ("converge", "pendulum", "--method", "rk4,rk4")),
        Case("converge-duplicate-alias", ("converge", "pendulum", "--method", "rk4", "--method", "classical")),
        Case("converge-plot-suffix", ("converge", "pendulum", *quick, "--plot", "p.gif")),
        Case("converge-plot-folder", ("converge", "pendulum", *quick, "--plot", "p.png"), {"p.png/inside": "x"}),
        Case("converge-plot-missing", ("converge", "pendulum", *quick, "--plot", "no/p.png")),
        Case("bench-tolerance-zero", ("bench", "pendulum", *quick, "--tolerances", "0")),
        Case("bench-tolerance-negative", ("bench", "pendulum", *quick, "--tolerances", "-1e-6")),
        Case("bench-tolerance-nan", ("bench", "pendulum", *quick, "--tolerances", "nan")),
        Case("bench-tolerance-one", ("bench", "pendulum", *quick, "--tolerances", "2")),
        Case("bench-duplicate-peers", ("bench", "pendulum", *quick, "--peers", "scipy:dop853,scipy:dop853")),
        Case("bench-duplicate-peers-case", ("bench", "pendulum", *quick, "--peers", "scipy:dop853,SCIPY:DOP853")),
        Case("bench-duplicate-peers-alias",
             ("bench", "pendulum", *quick, "--peers", "classical:rk4,classical:classical")),
        Case("bench-peer-is-method", ("bench", "pendulum", "--method", "classical:rk4", "--peers", "classical:rk4")),
        Case("bench-unknown-peer", ("bench", "pendulum", *quick, "--peers", "euler-maruyama")),
        Case("bench-peers-empty-names", ("bench", "pendulum", *quick, "--peers", ",")),
        Case("bench-repeats-zero", ("bench", "pendulum", *quick, "--repeats", "0")),
        Case("bench-repeats-huge", ("bench", "pendulum", *quick, "--repeats", "100000000")),
        Case("bench-ensemble-zero", ("bench", "pendulum", *quick, "--ensemble", "0")),
        Case("bench-ensemble-memory", ("bench", "pendulum", *quick, "--ensemble", "100000000000")),
        Case("bench-seed-negative", ("bench", "pendulum", *quick, "--ensemble", "2", "--seed", "-1")),
        Case("bench-steps-memory", ("bench", "pendulum", *quick, "--steps", "10,1000000000000")),
        Case("stress-long-steps-zero", ("stress", "pendulum", *quick, "--long-steps", "0")),
        Case("stress-long-steps-memory", ("stress", "pendulum", *quick, "--long-steps", "1000000000000")),
        Case("stress-long-h-nan", ("stress", "pendulum", *quick, "--long-h", "nan")),
        Case("stress-sweep-huge", ("stress", "pendulum", *quick, "--sweep-coarsest", "1000000000000")),
        Case("stress-round-off-memory", ("stress", "pendulum", *quick, "--round-off-steps", "10,20,1000000000000")),
        Case("modified-seed-negative", ("modified", "-m", "rk4", "-n", "3", "--seed", "-1")),
        Case("modified-order-huge", ("modified", "-m", "rk4", "-n", "99")),
        Case("modified-payload", ("modified", "-m", "t.toml", "-n", "3"),
             {"t.toml": toml(RK4, b=[PAYLOADS["import"], "1/3", "1/3", "1/6"])}),
        Case("compose-seed-huge", ("compose", "rk4,rk4", "--seed", "9" * 40)),
        Case("compose-too-many", ("compose", ",".join(["rk4"] * 9))),
        Case("compose-order-huge", ("compose", "rk4,rk4", "--order", "1000")),
        Case("show-payload", ("show", "t.json"), {"t.json": jsondoc(RK4, b=[PAYLOADS["lambda"], 0, 0, 0])}),
        Case("show-deep", ("show", "t.json"), {"t.json": "[" * 50_000}),
        Case("realisation-truncated-huge", ("check", "pendulum", "--realisation", "truncated:" + "9" * 5000)),
        Case("realisation-truncated-unicode", ("check", "pendulum", "--realisation", "truncated:\u00b2")),
        Case("realisation-payload", ("check", "pendulum", "--realisation", PAYLOADS["import"])),
        Case("problem-size-huge", ("check", "toda:99999999", "--samples", "1")),
        Case("problem-size-digits", ("check", "toda:" + "9" * 5000, "--samples", "1")),
        Case("problem-size-empty", ("check", "toda:", "--samples", "1")),
        Case("integrate-thp-bignum", ("integrate", "pendulum", "--method", "thp" + "9" * 5000, "--steps", "1")),
        Case("integrate-modified-zero", ("integrate", "pendulum", *quick, "--steps", "1", "--modified", "0")),
        Case("integrate-scipy-method", ("integrate", "pendulum", "--method", "scipy:bogus", "--steps", "1")),
        Case("converge-x0-nan", ("converge", "pendulum", *quick, "--x0", "nan,1")),
        Case("converge-x0-size", ("converge", "pendulum", *quick, "--x0", "1,2,3")),
        Case("converge-x0-nonfinite-h", ("converge", "s.toml", *quick, "--x0", "-3,0"),
             {"s.toml": toml(PENDULUM, hamiltonian="log(x1 + 2) + x2^2")}),
        Case("converge-workers-zero", ("converge", "pendulum", *quick, "--workers", "0")),
        Case("converge-workers-huge", ("converge", "pendulum", *quick, "--workers", "100000")),
        Case("memory-limit-env-bad", ("integrate", "pendulum", *quick, "--steps", "10"),
             env={"RKHP_MEMORY_LIMIT": "lots"}),
        Case("memory-limit-env-small", ("integrate", "pendulum", *quick, "--steps", "1000"),
             env={"RKHP_MEMORY_LIMIT": "1K"}),
        Case("check-failed-search", ("search", "--stages", "2", "--order", "3", "--restarts", "2", "--format", "json"),
             status=1),
        Case("check-failed-overclaim", ("verify", "t.toml", "--format", "json"), {"t.toml": toml(RK4, order=5)},
             status=1),
        Case("numerical-newton", ("integrate", "pendulum", *quick, "--h", "50", "--t-final", "500", "--format", "json"),
             status=1),
        Case("numerical-nonfinite",
             ("integrate", "s.toml", "--method", "classical:rk4", "--h", "10", "--format", "json"),
             {"s.toml": toml(PENDULUM, hamiltonian="x2^4/4 + x1^4/4", x0=[3.0, 3.0], t_final=100)}, status=1),
        Case("unknown-command", ("frobnicate",)),
        Case("unknown-option", ("trees", "--order", "3", "--colour")),
        Case("format-unknown", ("systems", "--format", "yaml")),
    ]


#: commands run (without limits) before the corpus, so that the few cases that integrate load the
#: compiled kernels from numba's cache instead of compiling them
WARM_UP = (("integrate", "pendulum", "--method", "rk4", "--steps", "20"),
           ("integrate", "pendulum", "--method", "classical:rk4", "--steps", "20"))

CASES = _payload_cases() + _expression_cases() + _spec_cases() + _file_cases() + _option_cases()


# --------------------------------------------------------------------------- running


def _write(folder: Path, files: dict) -> None:
    for name, content in files.items():
        if callable(content):
            content = content()
        path = folder / name.format(d=folder)
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, Link):
            os.mkfifo(path) if content == "fifo" else path.symlink_to(content)
        elif isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content.replace("{d}", str(folder)), encoding="utf-8")


class Outcome(NamedTuple):
    status: int | str
    stderr: str
    stdout: str
    wall: float
    cpu: float
    rss: int
    created: list




def _run(case: Case, folder: Path, server: ForkServer) -> Outcome:
    """Run one case in `folder`; its CPU time and peak memory come from wait4's resource usage."""
    folder.mkdir()
    _write(folder, case.files)
    before = {p.relative_to(folder) for p in folder.rglob("*")}
    out, err = folder.parent / "stdout", folder.parent / "stderr"
    out.touch()
    err.touch()
    answer = server.run({"args": [a.replace("{d}", str(folder)) for a in case.args], "cwd": str(folder),
                         "env": {**os.environ, **ENV, **case.env}, "stdout": str(out), "stderr": str(err),
                         "address_space": ADDRESS_SPACE, "cpu_seconds": CPU_SECONDS, "wall_seconds": WALL_GUARD})
    stdout, stderr = (f.read_bytes().decode("utf-8", "replace") for f in (out, err))
    after = {p.relative_to(folder) for p in folder.rglob("*")}
    return Outcome(answer["status"], stderr, stdout, answer["wall"], answer["cpu"], answer["rss"],
                   sorted(str(p) for p in after - before))


@pytest.fixture(scope="session")
def server():
    for args in WARM_UP:  # numba's cache: a case's 10 s of CPU must not include compiling the engine
        subprocess.run([sys.executable, "-m", "rkhp", *args], capture_output=True, check=True)
    forks = ForkServer()
    yield forks
    forks.close()


def test_corpus_size_and_names():
    assert len(CASES) >= 150
    assert len({c.name for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_hostile(case, server, tmp_path):
    o = _run(case, tmp_path / "case", server)
    assert o.status != "timeout", f"blocked: no answer within {WALL_GUARD} s"
    assert "Traceback" not in o.stderr, o.stderr[-2000:]
    assert o.status == case.status, (o.status, o.stderr[-2000:])
    assert not o.created, f"created {o.created}"
    if case.status:
        assert o.stderr.endswith("\n") and o.stderr.count("\n") == 1, o.stderr[-2000:]
        assert o.stderr.startswith("rkhp: "), o.stderr
    if "json" in case.args and o.stdout:  # valid JSON, no bare NaN or Infinity
        json.loads(o.stdout, parse_constant=lambda name: pytest.fail(f"bare {name} in the JSON output"))
    assert o.cpu <= CPU_SECONDS
    assert o.rss < ADDRESS_SPACE
