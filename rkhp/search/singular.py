"""Groebner bases and cofactors by Singular (https://www.singular.uni-kl.de), when it is installed.

Singular is optional: :func:`singular_path` finds the ``Singular`` program on PATH (or the one
named by ``RKHP_SINGULAR``); without it the proofs fall back on sympy. Each computation is a
child process stopped at its deadline:

- :func:`singular_basis`: a Groebner basis by ``slimgb`` (degree reverse lexicographic order;
  measured far faster than ``std`` on these systems: degenerate order 6 with 5 stages modulo 32003,
  2.9 s against no basis within 180 s), made reduced by ``std``, with the Krull dimension ``dim``
  and, when zero-dimensional, ``vdim`` (the number of complex solutions counted with
  multiplicity); over Q, or modulo a prime ``characteristic`` (evidence only: a basis [1] modulo
  p does not prove [1] over Q, the converse fails only for finitely many p);
- :func:`singular_cofactors`: ``liftstd``, the standard basis G with the matrix T such that
  G = F T; when G contains a nonzero constant g_k, the cofactors T[i, k] / g_k give
  1 = sum_i cofactor_i f_i, checked afterwards in exact arithmetic (:mod:`.certificates`).

The variables travel as x(1), ..., x(n) and are renamed on the way back.
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from ..base.errors import CheckFailed

#: Environment variable naming the Singular executable (default: ``Singular`` on PATH).
SINGULAR_ENV = "RKHP_SINGULAR"


@dataclass(frozen=True)
class SingularRun:
    """What one Singular computation returned.

    Attributes:
        finished: False when stopped at the deadline (the other fields are then empty).
        lines: the marked output lines (``BASIS ...``, ``POLY ...``), variables renamed.
        seconds: wall time of the child process.
        version: Singular's version line.
    """

    finished: bool
    lines: tuple[str, ...]
    seconds: float
    version: str


def singular_path() -> str | None:
    """The Singular executable, or None when it is not installed."""
    named = os.environ.get(SINGULAR_ENV)
    if named:
        return named if shutil.which(named) else None
    return shutil.which("Singular")


@functools.lru_cache(maxsize=4)
def singular_version(path: str) -> str:
    """Singular's own version line (e.g. ``Singular ... version 4.3.1``)."""
    try:
        out = subprocess.run([path, "--version"], stdin=subprocess.DEVNULL, capture_output=True,
                             text=True, timeout=30, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return "Singular (version unknown)"
    first = (out.stdout or out.stderr).strip().splitlines()
    return first[0] if first else "Singular"


def _script(variables, generators, body: str, characteristic: int = 0) -> str:
    rename = {v: f"x({k + 1})" for k, v in enumerate(variables)}
    pattern = re.compile(r"\b(" + "|".join(map(re.escape, variables)) + r")\b")
    polys = ",\n".join(pattern.sub(lambda m: rename[m.group(1)], g) for g in generators)
    return (f"ring r = {characteristic},(x(1..{len(variables)})),dp;\noption(redSB);\nideal I =\n{polys};\n"
            f"link out = \":w result.txt\";\n{body}\nclose(out);\nquit;\n")


_BASIS = """ideal G = std(slimgb(I));
int k;
write(out, "BASIS " + string(size(G)) + " " + string(dim(G)) + " " + string(vdim(G)));
for (k = 1; k <= ncols(G); k++) { write(out, "POLY " + string(G[k])); }
"""

_COFACTORS = """matrix T;
ideal G = liftstd(I, T);
int k; int j; int found = 0;
for (k = 1; k <= ncols(G); k++) { if (G[k] != 0 && deg(G[k]) == 0) { found = k; break; } }
if (found == 0) { write(out, "PROPER"); }
else {
  number lc = leadcoef(G[found]);
  write(out, "UNIT");
  for (j = 1; j <= nrows(T); j++) { write(out, "POLY " + string(T[j, found] / lc)); }
}
"""


def _run_script(path: str, variables, generators, body: str, deadline: float, on_wait=None,
         characteristic: int = 0) -> SingularRun:
    """Run the script until it ends or ``deadline`` (time.monotonic()); poll ``on_wait()``."""
    version = singular_version(path)
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="rkhp-singular-") as tmp:
        script = Path(tmp) / "job.sing"
        script.write_text(_script(variables, generators, body, characteristic))
        errors = open(Path(tmp) / "stderr.txt", "wb")  # closed in the finally clause
        proc = subprocess.Popen([path, "-q", "--no-rc", "--no-warn", str(script)], cwd=tmp,
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=errors)
        try:
            while proc.poll() is None:
                if time.monotonic() >= deadline:
                    proc.kill()
                    proc.wait()
                    return SingularRun(False, (), time.monotonic() - t0, version)
                if on_wait is not None:
                    on_wait()
                try:
                    proc.wait(timeout=min(0.25, max(0.0, deadline - time.monotonic())))
                except subprocess.TimeoutExpired:
                    pass
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            errors.close()
        seconds = time.monotonic() - t0
        result = Path(tmp) / "result.txt"
        if proc.returncode != 0 or not result.exists():
            err = (Path(tmp) / "stderr.txt").read_text(errors="replace").strip()
            raise CheckFailed(f"Singular failed (exit {proc.returncode}): {err[-300:]}")
        text = result.read_text()
    back = {f"x({k + 1})": v for k, v in enumerate(variables)}
    lines = tuple(re.sub(r"x\((\d+)\)", lambda m: back[m.group(0)], line)
                  for line in text.splitlines() if line.strip())
    return SingularRun(True, lines, seconds, version)


def singular_basis(path, variables, generators, deadline, on_wait=None,
                   characteristic: int = 0) -> SingularRun:
    """Reduced Groebner basis over Q (or modulo the prime ``characteristic``): lines
    ``BASIS size dim vdim`` then ``POLY g`` each."""
    return _run_script(path, variables, generators, _BASIS, deadline, on_wait, characteristic)


def singular_cofactors(path, variables, generators, deadline, on_wait=None) -> SingularRun:
    """Cofactors of 1 over Q: ``UNIT`` then one ``POLY g_i`` per generator, or ``PROPER``."""
    return _run_script(path, variables, generators, _COFACTORS, deadline, on_wait)
