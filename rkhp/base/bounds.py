"""Bounds on everything a user can ask for, checked before any work starts (docs/input.md).

Every number a command or a file gives is checked here against a named limit, so that bad or
unbounded input ends at once with one line (InputError, exit status 2) instead of a traceback, a
hang or a memory exhaustion. The memory a run would take is estimated from the arrays it allocates
(:func:`check_memory`) and refused above :data:`MEMORY_LIMIT` (or the ``RKHP_MEMORY_LIMIT``
environment variable). This module is light (no numpy): the command line checks its options with
it before importing anything heavy.
"""

from __future__ import annotations

import math
import numbers
import os
import re
import stat
import tempfile
from pathlib import Path

from .errors import InputError

# ----------------------------------------------------------------------------- limits

#: bytes of the arrays one command may allocate (estimated before the work starts); the
#: environment variable RKHP_MEMORY_LIMIT (bytes, or with a K/M/G suffix) replaces it
MEMORY_LIMIT = 2 * 1024**3
#: steps of one trajectory (beyond the memory limit anyway for every system but the smallest)
MAX_STEPS = 10**9
#: the most output times of one run (`integrate --t-eval`; each costs one step of the method)
MAX_OUTPUT_TIMES = 100_000
#: halvings of h in a convergence study (20 * 2^30 steps is far beyond the memory limit)
MAX_REFINEMENTS = 30
#: largest seed: seeds are 0 .. 2^64 - 1 (numpy's SeedSequence takes non-negative integers)
MAX_SEED = 2**64 - 1
#: restart budget of a search, per order
MAX_RESTARTS = 1_000_000
#: worker processes of a search
MAX_WORKERS = 256
#: seconds of a --time-limit (about 115 days)
MAX_SECONDS = 1e7
#: random points of `rkhp check`
MAX_SAMPLES = 1_000_000
#: timed repeats per point of `rkhp bench`
MAX_REPEATS = 1_000
#: starts of a `rkhp bench --ensemble`
MAX_ENSEMBLE = 1_000_000
#: rtol of the scipy peers: from this (scipy raises smaller values to 100 machine epsilons and an
#: atol of 1e-3 rtol then stalls the solver) to below 1
MIN_TOLERANCE = 1e-14
#: lines --show may list
MAX_SHOW = 1_000_000
#: dimension n of a system from a spec file (the Jacobi check handles n^3 triples)
MAX_DIMENSION = 64
#: stages of a tableau read from a file (the largest built-in one has 35)
MAX_STAGES = 100
#: an order a tableau file claims
MAX_CLAIMED_ORDER = 100
#: bytes read from an input file (spec, tableau); larger files are refused unread
MAX_FILE_BYTES = 8 * 1024**2
#: nesting of arrays and tables in a TOML or JSON file
MAX_NESTING = 32
#: |exponent| of a decimal tableau entry such as 1e-20, and its significant digits
MAX_DECIMAL_EXPONENT = 1000
MAX_DECIMAL_DIGITS = 2000
#: numbers of steps or tolerances in one comma-separated list
MAX_LIST = 1000

#: relative tolerance within which T/h counts as an integer (see :func:`step_plan`)
DIVIDES_TOLERANCE = 1e-9


# ----------------------------------------------------------------------------- numbers


def float_or_infinity(x) -> float:
    """float(x), or +-inf when x is beyond the float range (an int of 310 digits or more)."""
    try:
        return float(x)
    except OverflowError:
        return math.inf if x > 0 else -math.inf


def shown(value) -> str:
    """A value as an error message quotes it: its repr, cut to 40 characters."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def integer(value, what: str, low: int | None = None, high: int | None = None) -> int:
    """An integer low <= value <= high (booleans and floats are not integers)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{what} must be an integer, got {shown(value)}")
    if low is not None and value < low:
        raise InputError(f"{what} must be at least {low}, got {shown(value)}")
    if high is not None and value > high:
        raise InputError(f"{what} must be at most {high}, got {shown(value)}")
    return value


def number(value, what: str, low: float | None = None, high: float | None = None, *,
           low_open: bool = False, high_open: bool = False) -> float:
    """A finite float within [low, high] (or open ends); booleans and text are not numbers."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{what} must be a number, got {shown(value)}")
    try:
        x = float(value)
    except OverflowError:
        raise InputError(f"{what} is too large: {shown(value)}") from None
    if not math.isfinite(x):
        raise InputError(f"{what} must be finite, got {x}")
    if low is not None and (x < low or (low_open and x == low)):
        raise InputError(f"{what} must be {'>' if low_open else '>='} {low:g}, got {x:g}")
    if high is not None and (x > high or (high_open and x == high)):
        raise InputError(f"{what} must be {'<' if high_open else '<='} {high:g}, got {x:g}")
    return x


def positive(value, what: str) -> float:
    """A positive, finite number."""
    return number(value, what, 0.0, low_open=True)


def nonzero(value, what: str) -> float:
    """A finite, non-zero number (a signed step size or time: negative runs backwards)."""
    x = number(value, what)
    if x == 0.0:
        raise InputError(f"{what} must be non-zero, got 0")
    return x


def seed(value, what: str = "seed") -> int:
    """A seed: an integer from 0 to MAX_SEED."""
    return integer(value, what, 0, MAX_SEED)


def tolerance(value, what: str = "tolerance") -> float:
    """An rtol of the scipy peers: MIN_TOLERANCE <= value < 1."""
    return number(value, what, MIN_TOLERANCE, 1.0, high_open=True)


def parse_list(text: str, what: str, convert) -> tuple:
    """A comma-separated list, each item read by `convert(item_text)` (InputError naming it; an
    empty item, as in "1,,2" or "1,2,", is refused rather than dropped)."""
    items = [t.strip() for t in str(text).split(",")]
    if not any(items):
        raise InputError(f"{what}: empty list")
    if len(items) > MAX_LIST:
        raise InputError(f"{what}: {len(items)} values; at most {MAX_LIST}")
    if not all(items):
        raise InputError(f"{what}: an empty value in {shown(str(text))}")
    return tuple(convert(t) for t in items)


MAX_INT_DIGITS = 30
"""Most decimal digits of an integer read from text, a flag or a document (TOML and JSON alike)."""


def parse_int(text: str, what: str) -> int:
    """An integer written in decimal (at most MAX_INT_DIGITS digits, so that no bignum is ever parsed)."""
    s = text.strip()
    if not re.fullmatch(rf"[+-]?[0-9]{{1,{MAX_INT_DIGITS}}}", s):
        raise InputError(f"{what}: {shown(s)} is not a valid integer")
    return int(s)


#: a number as the options take it: ASCII decimal digits (Python's float() also reads other
#: scripts' digits and underscores, which no other reader of rkhp accepts)
DECIMAL = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")


def parse_float(text: str, what: str) -> float:
    """A finite float written as a decimal number (nan and inf are refused)."""
    s = text.strip()
    if len(s) > 100 or not DECIMAL.fullmatch(s):
        if s.lower().lstrip("+-") in ("nan", "inf", "infinity"):
            raise InputError(f"{what}: expected a finite number, got {shown(s)}")
        raise InputError(f"{what}: expected a number, got {shown(s)}")
    x = float(s)
    if not math.isfinite(x):
        raise InputError(f"{what}: expected a finite number, got {shown(s)}")
    return x


# ----------------------------------------------------------------------------- time steps


def check_step(h, n_steps, dim: int | None = None) -> tuple[float, int]:
    """A step size and a number of steps, as every integrator takes them: h a finite, non-zero real
    number (negative: a backward run, docs/compositions.md "Backward steps"; not text, not a bool),
    0 <= n_steps <= MAX_STEPS an integer (numpy's integers too; 0 steps: the start alone); with the
    dimension, the stored trajectory within the memory limit."""
    if type(h) is float and type(n_steps) is int and h != 0.0 and math.isfinite(h) and 0 <= n_steps <= MAX_STEPS:
        if dim is not None:  # the common case, checked without the general path's conversions
            check_trajectory(n_steps, dim)
        return h, n_steps
    if isinstance(h, bool) or not isinstance(h, numbers.Real):
        raise InputError(f"step size h must be a number, got {type(h).__name__} {shown(h)}")
    try:
        h = float(h)
    except OverflowError:
        raise InputError("step size h is too large for a float") from None
    h = nonzero(h, "step size h")
    if isinstance(n_steps, bool) or not hasattr(n_steps, "__index__"):
        raise InputError(f"number of steps must be an integer, got {shown(n_steps)}")
    n = integer(n_steps.__index__(), "number of steps", 0, MAX_STEPS)
    if dim is not None:
        check_trajectory(n, dim)
    return h, n


def _divisions(t_final: float, h: float) -> int:
    """The number of steps N = T/h when h divides T, else InputError.

    T and h are non-zero and of one sign (negative: a backward run). h divides T when T/h is
    within DIVIDES_TOLERANCE (relative) of an integer N >= 1: the run then reaches t = N h = T up
    to rounding. Otherwise it is refused, naming the nearest step sizes that divide T (never a run
    that stops short of T or overshoots it).
    """
    ratio = t_final / h
    if ratio > MAX_STEPS:
        raise InputError(f"--h {h:g} over T = {t_final:g} means {ratio:.3g} steps; at most {MAX_STEPS}")
    n = max(round(ratio), 1)
    if abs(ratio - n) > DIVIDES_TOLERANCE * max(ratio, 1.0):
        near = sorted({max(math.floor(ratio), 1), max(math.ceil(ratio), 1)})
        options = " or ".join(f"--h {t_final / k!r} ({k} step{'s' if k > 1 else ''})" for k in near)
        raise InputError(f"--h {h:g} does not divide T = {t_final:g} (T/h = {ratio:.6g}): a run would not end at T; "
                         f"use --steps N, or {options}")
    return n


def step_plan(t_final, steps: int | None, h: float | None) -> tuple[int, float]:
    """(N, h) from exactly one of --steps N (h = T/N) and --h (N = T/h, h must divide T); T and h
    may be negative (a backward run), of one sign."""
    if (steps is None) == (h is None):
        raise InputError("give exactly one of --steps and --h")
    t_final = nonzero(t_final, "T (--t-final)")
    if steps is not None:
        n = integer(steps, "--steps", 1, MAX_STEPS)
        return n, t_final / n
    h = nonzero(h, "--h")
    if (t_final > 0) != (h > 0):
        raise InputError(f"--h {h:g} and T = {t_final:g} have opposite signs: a run goes from 0 to T")
    return _divisions(t_final, h), h


def real_vector(values, what: str = "x0") -> list[float]:
    """A state from Python: a list, tuple or 1-d array of real numbers (int, float, Fraction, numpy
    reals), each finite; text, a mapping, a bool, a complex number or a nested list is refused
    (InputError), never converted silently."""
    if isinstance(values, (str, bytes, dict)) or not hasattr(values, "__iter__"):
        raise InputError(f"{what} must be a list of numbers, got {type(values).__name__}")
    shape = getattr(values, "shape", None)
    if shape is not None and len(shape) != 1:
        raise InputError(f"{what} must be a list of numbers, got an array of shape {tuple(shape)}")
    out = []
    for k, v in enumerate(values):
        if len(out) >= MAX_LIST:
            raise InputError(f"{what} has more than {MAX_LIST} components")
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise InputError(f"{what}[{k}] must be a real number, got {type(v).__name__} {shown(v)}")
        try:
            x = float(v)
        except OverflowError:
            raise InputError(f"{what}[{k}] is too large for a float") from None
        if not math.isfinite(x):
            raise InputError(f"{what}[{k}] must be finite, got {x}")
        out.append(x)
    return out


# ----------------------------------------------------------------------------- memory


def memory_limit() -> int:
    """MEMORY_LIMIT, or the RKHP_MEMORY_LIMIT environment variable (bytes; suffix K, M or G)."""
    text = os.environ.get("RKHP_MEMORY_LIMIT", "").strip()
    if not text:
        return MEMORY_LIMIT
    scale = {"K": 1024, "M": 1024**2, "G": 1024**3}.get(text[-1:].upper(), 1)
    digits = text[:-1] if scale > 1 else text
    if not (digits.isascii() and digits.isdigit()) or len(digits) > 15 or int(digits) == 0:
        raise InputError(f"RKHP_MEMORY_LIMIT must be a positive number of bytes (suffix K, M or G), got {text!r}")
    return int(digits) * scale


def size_text(nbytes: float) -> str:
    """A byte count for people: 1.5 GiB, 300 MiB."""
    for unit, scale in (("TiB", 1024.0**4), ("GiB", 1024.0**3), ("MiB", 1024.0**2), ("KiB", 1024.0)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes:.0f} B"


def check_memory(nbytes: float, what: str) -> None:
    """Refuse a run whose arrays would take more than the memory limit (InputError naming both)."""
    limit = memory_limit()
    if not nbytes <= limit:
        shown = size_text(nbytes) if math.isfinite(nbytes) and nbytes < 1e30 else f"{nbytes:.3g} B"
        raise InputError(f"{what} would need about {shown} of memory; the limit is {size_text(limit)} "
                         "(environment variable RKHP_MEMORY_LIMIT)")


def trajectory_bytes(steps: float, dim: int) -> float:
    """Bytes of one stored trajectory: states (N+1) x n, times N+1 and Newton counts N (8 bytes each)."""
    return 8.0 * (float(steps) + 1.0) * (dim + 2)


def check_trajectory(steps, dim: int, what: str = "the run") -> None:
    """The memory check of one stored trajectory of `steps` steps in dimension `dim`."""
    nbytes = trajectory_bytes(steps, dim)
    if not nbytes <= memory_limit():
        check_memory(nbytes, f"{what} ({steps} steps in dimension {dim})")


#: steps of all the trajectories of one study (`bench`: repeats x starts x steps x methods); at
#: the engine's 10^6 to 10^7 steps per second, 10^11 steps are hours of work
MAX_WORK_STEPS = 10**11


def check_work(steps: int, what: str) -> None:
    """Work whose size is known before it starts, refused with the estimate above MAX_WORK_STEPS."""
    if steps > MAX_WORK_STEPS:
        raise InputError(f"{what} would take about {steps:.2g} steps of the integrators (hours to years); "
                         f"the limit is {MAX_WORK_STEPS:.0e}")


#: bytes per tree of an enumeration: the tree objects and tables (290 measured at order 15)
BYTES_PER_TREE = 500
#: bytes per tree that `rkhp trees` prints (1.7 KB measured: trees --order 15 --format json)
BYTES_PER_PRINTED_TREE = 2000
#: bytes per order condition that `rkhp conditions` prints (3.4 KB measured at order 13, JSON)
BYTES_PER_CONDITION = 4000


# ----------------------------------------------------------------------------- write targets


def check_output_path(path, suffixes: tuple[str, ...] = (), what: str = "output file"):
    """A file the command will write, checked before the work starts: a known suffix, an existing
    writable folder, and no folder, device or pipe already at that name. Returns a Path.
    `what` names the file in messages (an option such as --plot)."""
    path = Path(path)
    if not str(path).strip():
        raise InputError(f"{what}: empty file name")
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(f"{what} {path}: unknown extension {path.suffix or '(none)'}; "
                         f"the name must end in {' or '.join(suffixes)}")
    try:  # a name too long, a loop of links: OSError from any of these
        return _checked_output_path(path, what)
    except OSError as exc:
        raise InputError(f"{what} {shown(str(path))}: {exc.strerror or exc}") from None


def _probe(folder: Path, what: str, path: Path) -> None:
    """Create and remove an empty file in the folder: a folder that takes no file although access()
    says it is writable (/proc, a read-only mount, for root) is refused now, not after the work."""
    try:
        fd, name = tempfile.mkstemp(prefix=".rkhp-probe.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise InputError(f"{what} {path}: cannot write in the folder {folder} ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(name)


def _checked_output_path(path: Path, what: str) -> Path:
    folder = path.parent
    if not folder.is_dir():
        reason = "is not a folder" if folder.exists() else "does not exist"
        raise InputError(f"{what} {path}: the folder {folder} {reason}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{what} {path}: the folder {folder} is not writable")
    _probe(folder, what, path)
    if path.is_symlink():
        return path  # never followed: rkhp.base.files refuses it or replaces the link itself
    if path.is_dir():
        raise InputError(f"{what} {path}: is a folder")
    if path.exists():
        if not stat.S_ISREG(path.stat().st_mode):
            raise InputError(f"{what} {path}: not a regular file (a device or a pipe)")
        if not os.access(path, os.W_OK):
            raise InputError(f"{what} {path}: not writable")
    return path

