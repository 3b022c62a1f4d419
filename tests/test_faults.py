"""Faults of the environment, not of the input: nothing breaks for good (docs/exit-status.md,
docs/engine.md "When the cache is damaged or cannot be written", docs/distributed.md).

Each test injects one fault (a damaged cache file, a signal, a killed parent, a closed stream, an
unusable folder, a lost scheduler, a memory limit, a full disk or stderr), then checks the one
line the command says, its exit status, that nothing is left behind, and that the numbers after
recovery are those of an undisturbed run. Runs that need a cache of their own copy the shared
cache's `taylor` folder (the tape interpreter's kernels: a few seconds to compile again) into a
private XDG_CACHE_HOME; nothing here recompiles the engine.
"""

from __future__ import annotations

import errno
import fnmatch
import json
import os
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import rkhp
from rkhp.base.errors import NumericalFailure, WriteFailed
from rkhp.taylor.compiler import PACKAGE, cache_dir

LINUX = sys.platform.startswith("linux")
ROOT = Path(__file__).resolve().parent.parent


def _rkhp(*args: str, env: dict | None = None, timeout: float = 300, **kwargs) -> subprocess.CompletedProcess:
    """`python -m rkhp ARGS` in a process of its own (its environment, its streams)."""
    kwargs.setdefault("capture_output", True)
    return subprocess.run([sys.executable, "-m", "rkhp", *args], env=env, text=True, timeout=timeout, **kwargs)


def _private_cache(tmp_path: Path, folders=("taylor",)) -> tuple[dict, Path]:
    """An environment whose kernel cache is a copy of the shared cache's ``folders`` (in an
    XDG_CACHE_HOME under tmp_path), and the copy's cache folder: its files can be damaged without
    touching the shared cache."""
    home = tmp_path / "xdg"
    folder = home / "rkhp" / "numba" / cache_dir().name
    folder.mkdir(parents=True)
    for name in folders:
        if (cache_dir() / name).is_dir():
            shutil.copytree(cache_dir() / name, folder / name)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(home)
    return env, folder


def _reference_check() -> dict:
    """The deviations of `rkhp check rigid-body --samples 3` computed here, on the shared cache."""
    from rkhp.systems import get_system
    from rkhp.systems.check import check_birealisation

    return check_birealisation(get_system("rigid-body"), samples=3, seed=0).to_json()["deviations"]


CHECK = ("check", "rigid-body", "--samples", "3", "--format", "json")


def _kernel_files() -> list[Path]:
    """numba's cache files under the sources (numba's in-tree locator writes there)."""
    return sorted(PACKAGE.rglob("*.nbi")) + sorted(PACKAGE.rglob("*.nbc"))


# --------------------------------------------------------------------------- a damaged cache


#: damaged files, and how many of the two signatures each sends to a compile


# --------------------------------------------------------------------------- an unusable cache folder


# --------------------------------------------------------------------------- SIGTERM and SIGHUP


def _handles(pid: int, signum: int) -> bool:
    """Whether process ``pid`` has a handler for ``signum`` (the SigCgt mask of /proc/PID/status;
    True where there is no /proc to ask)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("SigCgt:"):
                    return bool(int(line.split()[1], 16) >> (signum - 1) & 1)
    except OSError:
        return True
    return True


def _start(args, signum: int, cwd=None, **kwargs) -> subprocess.Popen:
    """`python -m rkhp ARGS`, returned once it handles ``signum`` (the command's handler, installed
    when the command starts: before it, the default action ends a process still starting)."""
    proc = subprocess.Popen([sys.executable, "-m", "rkhp", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=cwd, **kwargs)
    deadline = time.monotonic() + 60
    while proc.poll() is None and not _handles(proc.pid, signum) and time.monotonic() < deadline:
        time.sleep(0.005)
    return proc


LONG_CONVERGE = ("converge", "pendulum", "--method", "euler", "--steps", "20", "--refinements", "19")

SIGNAL_DURING_A_ROW = r'''
import os, signal, sys
from rkhp.integrators import methods

integrate = methods.Method.integrate
SIGNUM = int(sys.argv[1])


def signalled(self, system, h, n_steps, x0=None):
    """The method, its run of 160 steps met by the signal (as a scheduler's time limit would)."""
    if n_steps == 160:
        os.kill(os.getpid(), SIGNUM)
    return integrate(self, system, h, n_steps, x0)


methods.Method.integrate = signalled
from rkhp_cli.main import main

sys.argv = ["rkhp", "converge", "rigid-body", "--method", "rk4", "--steps", "20,40,80,160,320"]
main()
'''


@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_sigterm_and_sighup_end_a_study_as_ctrl_c_does(signum, status):
    """A batch scheduler's time limit (SIGTERM) or a closed session (SIGHUP) during the fourth row
    of a study: the three rows finished are printed, one line on stderr naming the signal, status
    128 + signal."""
    proc = subprocess.run([sys.executable, "-c", SIGNAL_DURING_A_ROW, str(int(signum))], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == status, (proc.returncode, proc.stderr[-3000:])
    name = signal.Signals(signum).name
    assert proc.stderr == f"rkhp: interrupted by {name}: the rows finished so far are shown\n"
    steps = [int(line.split()[1]) for line in proc.stdout.splitlines() if re.match(r"\s+[0-9.]+\s+\d+\s", line)]
    assert steps == [20, 40, 80], proc.stdout


def test_sigterm_from_outside_is_never_a_traceback():
    """SIGTERM sent to a running study from outside (`timeout`, `docker stop`), a few seconds in:
    status 143 and one line (or the study finished first: status 0)."""
    proc = _start(LONG_CONVERGE, signal.SIGTERM)
    time.sleep(3.0)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=120)
    assert "Traceback" not in err and proc.returncode in (143, 0), (proc.returncode, err[-3000:])
    if proc.returncode:
        assert err.count("\n") == 1 and err.startswith("rkhp: interrupted by SIGTERM"), err


def test_a_signal_ignored_at_the_start_stays_ignored():
    """`nohup` starts a command with SIGHUP ignored: the command does not handle it."""
    proc = subprocess.Popen([sys.executable, "-m", "rkhp", *LONG_CONVERGE], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN))
    try:
        deadline = time.monotonic() + 60
        while proc.poll() is None and not _handles(proc.pid, signal.SIGTERM) and time.monotonic() < deadline:
            time.sleep(0.005)
        assert not _handles(proc.pid, signal.SIGHUP)
        proc.send_signal(signal.SIGHUP)
        time.sleep(0.5)
        assert proc.poll() is None  # still running
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143 and err.startswith("rkhp: interrupted by SIGTERM")


# --------------------------------------------------------------------------- workers die with their parent


# --------------------------------------------------------------------------- closed standard streams


def _with_closed(fd: int, *args: str, cwd=None) -> subprocess.CompletedProcess:
    """`python -m rkhp ARGS` with file descriptor ``fd`` closed (`>&-` or `2>&-`)."""
    redirect = {1: ">&-", 2: "2>&-"}[fd]
    command = " ".join([f"'{sys.executable}'", "-m", "rkhp", *args, redirect])
    return subprocess.run(["bash", "-c", command], stdout=subprocess.PIPE if fd != 1 else None,
                          stderr=subprocess.PIPE if fd != 2 else None, text=True, timeout=300, cwd=cwd)


def test_a_closed_stdout_is_one_line_and_status_1():
    proc = _with_closed(1, "systems")
    assert proc.returncode == 1
    assert proc.stderr == "rkhp: error: cannot write the output: Bad file descriptor\n"


def test_a_closed_stdout_is_not_taken_by_an_output_file(tmp_path):
    """With stdout closed, the first file rkhp opens would get its number and the table would be
    written into it: the trajectory file holds its rows only."""
    proc = _with_closed(1, "integrate", "rigid-body", "--method", "rk4", "--steps", "10", "--output", "t.csv",
                        cwd=tmp_path)
    assert proc.returncode == 1 and "Bad file descriptor" in proc.stderr
    rows = [line for line in (tmp_path / "t.csv").read_text().splitlines() if not line.startswith("#")]
    assert rows[0].startswith("t,x1,x2,x3") and len(rows) == 12


@pytest.mark.parametrize("args, status", [(("verify", "no-such-tableau"), 2), (("systems",), 0)])
def test_the_status_does_not_depend_on_stderr(args, status):
    """Bad input is 2 (success 0) with stderr closed or on a full device, as with a terminal."""
    closed = _with_closed(2, *args)
    assert closed.returncode == status
    if os.path.exists("/dev/full"):
        with open("/dev/full", "w") as full:
            proc = subprocess.run([sys.executable, "-m", "rkhp", *args], stdout=subprocess.PIPE, stderr=full,
                                  text=True, timeout=300)
        assert proc.returncode == status


def test_a_failed_check_is_1_with_stderr_closed(tmp_path):
    path = tmp_path / "over.toml"
    path.write_text('order = 5\nA = [["0","0","0","0"],["1/2","0","0","0"],["0","1/2","0","0"],'
                    '["0","0","1","0"]]\nb = ["1/6","1/3","1/3","1/6"]\n')
    assert _with_closed(2, "verify", str(path)).returncode == 1


# --------------------------------------------------------------------------- a Dask scheduler


# --------------------------------------------------------------------------- memory


def _limited(megabytes: int, *args: str) -> subprocess.CompletedProcess:
    """`python -m rkhp ARGS` under a limit of its address space (`ulimit -v`)."""
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (megabytes * 2**20, megabytes * 2**20))

    return subprocess.run([sys.executable, "-m", "rkhp", *args], capture_output=True, text=True, timeout=300,
                          preexec_fn=limit)


MEMORY_LINE = re.compile(r"rkhp: error: out of memory[^\n]*\(the process's memory limit, `ulimit -v`, or the "
                         r"machine's; docs/input.md#memory\)\n")


@pytest.mark.skipif(not LINUX, reason="address-space limits as on Linux")
def test_an_array_beyond_the_memory_limit_is_one_line():
    """40 million steps (rkhp's estimate 1.28 GB, under its own 2 GiB limit) under `ulimit -v`
    1.27 GB: numpy's _ArrayMemoryError as one line, status 1."""
    proc = _limited(1269, "integrate", "pendulum", "--steps", "40000000")
    assert proc.returncode == 1 and MEMORY_LINE.fullmatch(proc.stderr), proc.stderr[-3000:]


@pytest.mark.skipif(not LINUX, reason="address-space limits as on Linux")
def test_a_compiler_that_cannot_be_loaded_is_out_of_memory():
    """Under `ulimit -v` 390 MB numba's compiler library (libllvmlite.so) cannot be mapped: one
    line, status 1 (it was a 65-line traceback)."""
    proc = _limited(390, "integrate", "pendulum", "--steps", "200")
    assert proc.returncode == 1 and MEMORY_LINE.fullmatch(proc.stderr), proc.stderr[-3000:]


def test_what_says_that_memory_ran_out():
    from rkhp_cli.main import is_out_of_memory, out_of_memory

    not_mapped = OSError("Could not find/load shared object file 'libllvmlite.so'")  # llvmlite's, from:
    not_mapped.__context__ = OSError("libllvmlite.so: failed to map segment from shared object")
    assert is_out_of_memory(not_mapped)
    assert "a shared library could not be loaded: failed to map segment" in out_of_memory(not_mapped)
    assert is_out_of_memory(MemoryError()) and is_out_of_memory(OSError(errno.ENOMEM, "Cannot allocate memory"))
    assert not is_out_of_memory(OSError(errno.ENOENT, "No such file"))


# --------------------------------------------------------------------------- a full disk for --output and --plot


# --------------------------------------------------------------------------- rkhp check's tolerance


# --------------------------------------------------------------------------- rkhp.integrate


