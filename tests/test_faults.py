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
from child_signals import default_signals

import rkhp
from rkhp.base.errors import NumericalFailure, WriteFailed
from rkhp.base.json_form import json_form
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

    return json_form(check_birealisation(get_system("rigid-body"), samples=3, seed=0))["deviations"]


CHECK = ("check", "rigid-body", "--samples", "3", "--format", "json")


def _kernel_files() -> list[Path]:
    """numba's cache files under the sources (numba's in-tree locator writes there)."""
    return sorted(PACKAGE.rglob("*.nbi")) + sorted(PACKAGE.rglob("*.nbc"))


# --------------------------------------------------------------------------- a damaged cache


TINY = "import numba\n\n\n@numba.njit(cache=True)\ndef twice(x):\n    return x + x\n"

HEALING = r'''
import json, random, shutil, sys
import importlib.util
from pathlib import Path

from rkhp.taylor.compiler import numba  # noqa: F401 - numba with rkhp's patches: a robust cache

module_file, cache, pristine = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3])


def run():
    """A fresh dispatcher of `twice` (a new module object), called at two signatures."""
    spec = importlib.util.spec_from_file_location("tiny", module_file)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    values = [module.twice(1.5), module.twice(3)]
    stats = module.twice.stats
    return values, sum(stats.cache_hits.values()), sum(stats.cache_misses.values())


def damage(mode):
    index = next(cache.rglob("*.nbi"))
    data = sorted(cache.rglob("*.nbc"))
    noise = random.Random(mode)
    if mode == "empty index":
        index.write_bytes(b"")
    elif mode == "garbage index":
        index.write_bytes(noise.randbytes(3000))
    elif mode == "truncated index":
        index.write_bytes(index.read_bytes()[:40])
    elif mode == "truncated data":
        data[0].write_bytes(data[0].read_bytes()[: data[0].stat().st_size // 2])
    elif mode == "garbage data":
        data[0].write_bytes(noise.randbytes(data[0].stat().st_size))
    elif mode == "swapped data":
        first, second = data[0].read_bytes(), data[1].read_bytes()
        data[0].write_bytes(second)
        data[1].write_bytes(first)


first = run()
shutil.copytree(cache, pristine)
report = {"first": first}
for mode in sys.argv[4:]:
    shutil.rmtree(cache)
    shutil.copytree(pristine, cache)
    damage(mode)
    report[mode] = [run(), run()]
report["left"] = [p.name for p in cache.rglob("*") if ".tmp." in p.name]
print(json.dumps(report))
'''

#: damaged files, and how many of the two signatures each sends to a compile
DAMAGES = {"empty index": 2, "garbage index": 2, "truncated index": 2, "truncated data": 1, "garbage data": 1,
           "swapped data": 2}


def test_damaged_cache_files_cost_one_compile(tmp_path):
    """A kernel cached at two signatures (float64, int64), its cache files then damaged as a disk
    full during a save, a crash or a bad copy leave them: each damaged entry is compiled once
    (a miss, never an error: numba's own reader raises EOFError, UnpicklingError or SystemError,
    or runs the other signature's machine code), the values are right, and the next fresh
    dispatcher loads both from the repaired files."""
    module = tmp_path / "tiny_kernel.py"
    module.write_text(TINY)
    cache = tmp_path / "numba-cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    proc = subprocess.run([sys.executable, "-c", HEALING, str(module), str(cache), str(tmp_path / "pristine"),
                           *DAMAGES], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout)
    assert report["first"] == [[3.0, 6], 0, 2]  # compiled at both signatures, saved
    for mode, compiled in DAMAGES.items():
        damaged, repaired = report[mode]
        assert damaged == [[3.0, 6], 2 - compiled, compiled], mode
        assert repaired == [[3.0, 6], 2, 0], mode
    assert report["left"] == []


def _run_tape_index(folder: Path) -> Path:
    return next((folder / "taylor").glob("interpreter.run_tape-*.nbi"))


def test_an_empty_index_is_not_an_interrupt_and_heals(tmp_path):
    """The tape interpreter's index emptied (numba reads it with EOFError, which click took for
    Ctrl-C: `rkhp: interrupted`, status 130): the check runs, compiles the interpreter once and
    gives the numbers of the shared cache; the next run loads the repaired index."""
    env, folder = _private_cache(tmp_path)
    index = _run_tape_index(folder)
    index.write_bytes(b"")
    first = _rkhp(*CHECK, env=env)
    assert first.returncode == 0 and first.stderr == "", first.stderr[-3000:]
    reference = _reference_check()
    assert json.loads(first.stdout)["deviations"] == reference
    assert index.stat().st_size > 0
    script = ("import json, sys; from rkhp.taylor.compiler import is_cached; "
              "from rkhp.taylor.interpreter import run_tape; print(json.dumps(is_cached(run_tape, 'Tape(')))")
    loaded = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert json.loads(loaded.stdout) is True, loaded.stderr  # the interpreter for plain tapes is cached again
    again = _rkhp(*CHECK, env=env)
    assert again.returncode == 0 and json.loads(again.stdout)["deviations"] == reference


@pytest.mark.slow
def test_rkhp_compile_repairs_a_damaged_cache(tmp_path):
    """`rkhp compile` on a cache whose interpreter index is garbage: status 0, the interpreter
    compiled again for every class of tapes, then a second compile has nothing to do."""
    env, folder = _private_cache(tmp_path, ("taylor", "integrators"))
    _run_tape_index(folder).write_bytes(random.Random(0).randbytes(3000))
    first = _rkhp("compile", "--format", "json", env=env, timeout=900)
    assert first.returncode == 0 and first.stderr == "", first.stderr[-3000:]
    assert all("rkhp.taylor.interpreter.run_tape" in c["compiled"] for c in json.loads(first.stdout)["classes"])
    second = _rkhp("compile", "--format", "json", env=env, timeout=900)
    assert second.returncode == 0 and all(c["compiled"] == [] for c in json.loads(second.stdout)["classes"])


FULL_CACHE_DISK = r'''
import errno, os, sys
from numba.core import caching


def full(self, name, data):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


caching.IndexDataCacheFile._save_data = full  # every save into the cache meets a full disk
from rkhp_cli.main import main

sys.argv = ["rkhp", *sys.argv[1:]]
main()
'''


def test_a_full_disk_under_the_cache_is_a_warning_not_the_output(tmp_path):
    """The interpreter must compile (its index removed) and its save meets a full disk: one
    warning line naming the cache folder, status 0, the right numbers; not "cannot write the
    output", which is stdout's error."""
    env, folder = _private_cache(tmp_path)
    _run_tape_index(folder).unlink()
    proc = subprocess.run([sys.executable, "-c", FULL_CACHE_DISK, *CHECK], env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stderr == (f"rkhp: warning: cannot save compiled kernels in the cache folder {folder} "
                           "(No space left on device): later runs compile them again (docs/engine.md)\n")
    assert json.loads(proc.stdout)["deviations"] == _reference_check()


# --------------------------------------------------------------------------- an unusable cache folder


def test_an_unusable_cache_folder_is_said_once_and_falls_back(tmp_path):
    """XDG_CACHE_HOME naming a file: one warning line, the kernels cached in the documented
    fallback (here already holding the interpreter), the right numbers, and nothing written
    into the sources' __pycache__."""
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file")
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(XDG_CACHE_HOME=str(blocker), TMPDIR=str(temporary))
    fallback = temporary / f"rkhp-cache-{os.getuid()}" / "numba" / cache_dir().name  # docs/engine.md
    shutil.copytree(cache_dir() / "taylor", fallback / "taylor")
    before = _kernel_files()
    proc = _rkhp(*CHECK, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    preferred = blocker / "rkhp" / "numba" / cache_dir().name
    assert proc.stderr == (f"rkhp: warning: the kernel cache folder {preferred} cannot be used (Not a directory): "
                           f"using {fallback} (docs/engine.md)\n")
    assert json.loads(proc.stdout)["deviations"] == _reference_check()
    assert _kernel_files() == before


def test_no_usable_folder_is_said_and_never_the_sources(tmp_path):
    """Neither the cache folder nor the fallback can be used (another file where the fallback's
    folder would be): the warning gives both reasons, and rkhp's kernels are still placed in the
    cache folder (whose saves then fail), never in the sources' __pycache__ by numba's in-tree
    locator."""
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file")
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    (temporary / f"rkhp-cache-{os.getuid()}").write_text("someone's file")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(XDG_CACHE_HOME=str(blocker), TMPDIR=str(temporary))
    script = ("import json, warnings\nwith warnings.catch_warnings(record=True) as said:\n"
              "    warnings.simplefilter('always')\n    import rkhp.taylor.compiler as c\n"
              "    from rkhp.taylor.interpreter import run_tape\n"
              "print(json.dumps({'folder': c.RKHP_CACHE_DIR, 'said': [str(w.message) for w in said],"
              " 'kernels': run_tape._cache.cache_path}))")
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout)
    preferred = blocker / "rkhp" / "numba" / cache_dir().name
    assert report["folder"] == str(preferred)
    assert report["kernels"] == str(preferred / "taylor")
    assert len(report["said"]) == 1 and "Not a directory" in report["said"][0]
    assert "File exists" in report["said"][0] and "every run compiles them" in report["said"][0]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root writes read-only folders")
def test_a_read_only_cache_folder_falls_back(tmp_path):
    from rkhp.taylor.kernel_cache import usable_folder

    home = tmp_path / "home"
    home.mkdir(mode=0o500)
    try:
        chosen = usable_folder(home / "rkhp" / "numba" / "0123456789abcdef")
    finally:
        home.chmod(0o700)
    assert chosen.reason is not None and chosen.path != home / "rkhp" / "numba" / "0123456789abcdef"


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
                            text=True, cwd=cwd, preexec_fn=default_signals, **kwargs)
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
                          text=True, timeout=300, preexec_fn=default_signals)
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


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_while_the_command_starts_is_its_line(signum):
    """SIGTERM or SIGHUP as soon as the process handles it (during its imports, before the
    command's own handler): the same one line and status, not a silent end."""
    proc = _start(LONG_CONVERGE, signum)
    proc.send_signal(signum)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signum, (proc.returncode, err[-3000:])
    assert err.startswith(f"rkhp: interrupted by {signal.Signals(signum).name}") and err.count("\n") == 1, err


SLOW_DISK = r'''
import sys, time
from rkhp.base import files


def slow(path):
    """A slow disk: flushing the written content takes a minute."""
    time.sleep(60)


files._sync = slow
from rkhp_cli.main import main

sys.argv = ["rkhp", *sys.argv[1:]]
main()
'''


def test_a_signal_while_the_output_is_written_leaves_nothing(tmp_path):
    """SIGTERM while `--output` is being written (its temporary file there, its content being
    flushed to a slow disk): status 143, one line, neither the file nor its temporary left. The
    temporary's name matches the glob docs/input.md gives, `.NAME.*.tmp`."""
    proc = subprocess.Popen([sys.executable, "-c", SLOW_DISK, "integrate", "rigid-body", "--method", "rk4",
                             "--steps", "1000", "--output", "traj.csv"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while proc.poll() is None and not list(tmp_path.glob(".traj.csv.*.tmp")) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert proc.poll() is None and _handles(proc.pid, signal.SIGTERM), proc.communicate()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 143 and err == "rkhp: interrupted by SIGTERM\n", err[-3000:]
    assert list(tmp_path.iterdir()) == []


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


def _children(pid: int) -> list[int]:
    """The child processes of ``pid`` (Linux: /proc/PID/task/*/children)."""
    found = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            found += [int(c) for c in task.read_text().split()]
        except OSError:
            pass
    return found


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead and not yet reaped, does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def _wait_for_children(proc, count: int, seconds: float = 120) -> list[int]:
    deadline = time.monotonic() + seconds
    while proc.poll() is None and len(_children(proc.pid)) < count and time.monotonic() < deadline:
        time.sleep(0.05)
    return _children(proc.pid)


def _gone_within(pids, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while any(_alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return not any(_alive(pid) for pid in pids)


BENCH_ON_WORKERS = ("bench", "pendulum", "--method", "rk4", "--repeats", "200", "--workers", "2")


def _running_with_workers(args, **kwargs):
    """`rkhp ARGS` started in a session of its own, once its two workers run and a second has
    passed: (the process, the workers' pids)."""
    proc = _start(args, signal.SIGTERM, start_new_session=True, **kwargs)
    workers = _wait_for_children(proc, 2)
    assert len(workers) >= 2, workers
    time.sleep(1.0)
    return proc, workers


@pytest.mark.skipif(not LINUX, reason="reads /proc")
def test_killing_the_parent_kills_its_workers():
    """`kill -9` of `rkhp bench --workers 2`: its two workers end within seconds (they would
    compute for minutes, orphaned)."""
    proc, workers = _running_with_workers(BENCH_ON_WORKERS)
    proc.kill()
    proc.communicate(timeout=60)
    assert _gone_within(workers, 10), [pid for pid in workers if _alive(pid)]


@pytest.mark.skipif(not LINUX, reason="reads /proc")
def test_sigterm_of_the_parent_stops_its_workers_at_once():
    """SIGTERM of `rkhp bench --workers 2`: status 143 and one line within seconds, not after the
    workers' running tasks; no worker left."""
    proc, workers = _running_with_workers(BENCH_ON_WORKERS)
    proc.send_signal(signal.SIGTERM)
    start = time.monotonic()
    out, err = proc.communicate(timeout=60)
    assert time.monotonic() - start < 15
    # the run's cost notice (docs/methods.md) may come first; the interruption is the one line after it
    *before, last = err.splitlines()
    assert proc.returncode == 143 and last == "rkhp: interrupted by SIGTERM: the points finished so far are shown"
    assert all(line.startswith("rkhp: note: ") for line in before), before
    assert _gone_within(workers, 10)


@pytest.mark.skipif(not LINUX, reason="reads /proc")
def test_killing_rkhp_compile_kills_its_compile_workers(tmp_path):
    """`kill -9` of `rkhp compile --jobs 2` on an empty cache, both workers compiling: they end
    within seconds."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    proc, workers = _running_with_workers(("compile", "--jobs", "2"), env=env)
    proc.kill()
    proc.communicate(timeout=60)
    assert _gone_within(workers, 10), [pid for pid in workers if _alive(pid)]


def test_a_worker_started_after_its_parent_ended_ends_at_once():
    """die_with_parent in a process whose parent has already ended (the race between the fork
    and the parent-death signal being set: the process was given the pid of a parent that is no
    longer its parent) ends at once; with its parent alive it goes on."""
    script = ("import os, sys\nfrom rkhp.base.executors import die_with_parent\n"
              "die_with_parent(int(sys.argv[1]))\nprint('alive')\n")
    ended = subprocess.run([sys.executable, "-c", script, "1"], capture_output=True, text=True, timeout=60)
    assert ended.returncode == 1 and ended.stdout == ""  # its parent is this process, not pid 1
    alive = subprocess.run([sys.executable, "-c", script, str(os.getpid())], capture_output=True, text=True,
                           timeout=60)
    assert alive.returncode == 0 and alive.stdout == "alive\n"


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


def _http_server() -> tuple[socket.socket, int]:
    """A server on the loopback that answers every connection as a web server does to a request
    it cannot read (an HTTP 400), as a Dask dashboard does."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(16)

    def answer(conn):
        with conn:
            try:
                conn.recv(65536)
                conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 11\r\nConnection: close\r\n\r\n"
                             b"Bad Request")
            except OSError:
                pass

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            threading.Thread(target=answer, args=(conn,), daemon=True).start()

    threading.Thread(target=serve, daemon=True).start()
    return server, server.getsockname()[1]


def test_a_server_that_is_not_a_scheduler_is_one_line_at_once():
    """`--scheduler` at a web server's port: one line saying so, status 2, within seconds (it was
    a line about allocating 3.07 EiB, then a Client.__del__ traceback and 20 s of waiting)."""
    pytest.importorskip("distributed")
    server, port = _http_server()
    try:
        start = time.monotonic()
        proc = _rkhp("converge", "pendulum", "--method", "rk4", "--scheduler", f"tcp://127.0.0.1:{port}")
        seconds = time.monotonic() - start
    finally:
        server.close()
    assert proc.returncode == 2
    assert proc.stderr == (f"rkhp: error: the server at tcp://127.0.0.1:{port} is not a Dask scheduler: it does "
                           "not speak Dask's protocol (MemoryError) (a scheduler listens on port 8786 by default; "
                           "8787 is its dashboard)\n")
    assert seconds < 15  # the process start included; it was 21.6 s, most of it after the line


def test_a_scheduler_killed_during_a_run_is_one_line():
    """The scheduler killed during `converge --scheduler`: one line naming it, status 1, within
    seconds; none of distributed's tracebacks."""
    pytest.importorskip("distributed")
    from distributed import Client

    from rkhp.base.executors import loopback_cluster

    def tasks(dask_scheduler):
        return len(dask_scheduler.tasks)

    with loopback_cluster(2) as cluster, Client(cluster.address, set_as_default=False) as client:
        proc = _start((*LONG_CONVERGE, "--scheduler", cluster.address), signal.SIGTERM)
        deadline = time.monotonic() + 120
        while proc.poll() is None and not client.run_on_scheduler(tasks) and time.monotonic() < deadline:
            time.sleep(0.1)  # until the study's tasks are on the cluster
        assert proc.poll() is None, proc.communicate()
        cluster.scheduler.kill()
        start = time.monotonic()
        out, err = proc.communicate(timeout=120)
        assert time.monotonic() - start < 20
    assert proc.returncode == 1, err[-3000:]
    assert re.fullmatch(f"rkhp: error: lost the Dask scheduler at {re.escape(cluster.address)} during the run: "
                        r"its tasks were cancelled( \(scheduler-connection-lost\))?; the tasks not finished "
                        r"cannot be had\n", err), err


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


def _full_disk(monkeypatch):
    from rkhp.base import files

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(files.os, "fsync", full)


def test_a_full_disk_for_output_is_a_failure_not_bad_input(tmp_path, monkeypatch):
    """The run is done when --output meets a full disk: status 1 (2 says that nothing was
    computed), one line naming the file, nothing left in the folder."""
    from cli_run import in_process

    _full_disk(monkeypatch)
    target = tmp_path / "traj.csv"
    ran = in_process(("integrate", "rigid-body", "--method", "rk4", "--steps", "10", "--output", str(target)), None)
    assert ran.returncode == 1
    assert ran.stderr == (f"rkhp: error: trajectory file {target}: cannot write the file (No space left on "
                          "device); nothing was written\n")
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_for_a_plot_is_a_failure_not_bad_input(tmp_path, monkeypatch):
    from cli_run import in_process

    _full_disk(monkeypatch)
    target = tmp_path / "c.png"
    ran = in_process(("converge", "rigid-body", "--method", "rk4", "--steps", "20,40,80", "--plot", str(target)), None)
    assert ran.returncode == 1 and ran.stderr.count("\n") == 1 and "No space left on device" in ran.stderr
    assert list(tmp_path.iterdir()) == []


def test_the_temporary_file_matches_the_documented_glob(tmp_path):
    """docs/input.md names the temporaries `.NAME.*.tmp`: a leftover (an interrupted copy, a
    crash) is found by that glob."""
    from rkhp.base.files import atomic_path

    documented = re.search(r"named\s+`(\.NAME\.\*\.tmp)`", (ROOT / "docs" / "input.md").read_text()).group(1)
    for name in ("traj.csv", "plot.png", "found.toml", "data"):
        with atomic_path(tmp_path / name) as tmp:
            assert fnmatch.fnmatch(tmp.name, documented.replace("NAME", name)), tmp.name
            tmp.write_text("x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "found.toml", "plot.png", "traj.csv"]


def test_a_failed_write_is_write_failed_not_input_error(tmp_path, monkeypatch):
    from rkhp.base.errors import InputError
    from rkhp.base.files import write_atomic

    _full_disk(monkeypatch)
    with pytest.raises(WriteFailed, match="No space left") as caught:
        write_atomic(tmp_path / "t.toml", "A = [[0]]\n")
    assert not isinstance(caught.value, InputError)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- rkhp check's tolerance


def _blocks(n: int) -> str:
    """A spec of the general family on R^n (n even): n/2 canonical planes, each with the Poisson
    bracket {x_2k-1, x_2k} = 1 + x_2k-1^2 + x_2k^2 of its own variables. Each block is a 2-d
    structure (Poisson for every function) and the blocks commute: Poisson by construction."""
    rows = [["0"] * n for _ in range(n)]
    for k in range(0, n, 2):
        size = f"(1 + x{k + 1}^2 + x{k + 2}^2)"
        rows[k][k + 1], rows[k + 1][k] = size, f"-{size}"
    energy = " + ".join(f"x{i + 1}^2/2" for i in range(n))
    x0 = [0.3 * (i + 1) / n for i in range(n)]
    return (f'name = "blocks{n}"\nfamily = "general"\npoisson = {json.dumps(rows)}\n'
            f'hamiltonian = "{energy}"\nx0 = {x0}\n')


def test_check_does_not_call_a_correct_system_wrong(tmp_path):
    """An 8-variable structure of size 1 + |x|^2, Poisson by construction: seed 7 put a sample's
    {beta_i, beta_j} 1.07e-12 off pi against a fixed 1e-12, so the check failed it. Measured
    against the size of each bracket (2n max|dF| max|dG|), every axiom holds at 1e-12 with room,
    and the sizes are said."""
    from rkhp.systems import get_system
    from rkhp.systems.check import TOLERANCE_RULE, check_birealisation

    path = tmp_path / "blocks8.toml"
    path.write_text(_blocks(8))
    system = get_system(str(path))
    result = check_birealisation(system, samples=100, seed=7)
    assert result.ok and max(result.deviations.values()) < 1e-13, result.deviations
    assert result.scale > 100  # the brackets' size: round-off of size 1e-16 x scale would have failed
    document = json_form(result)
    assert document["tolerance"] == 1e-12 and document["tolerance_rule"] == TOLERANCE_RULE
    assert document["scale"] == result.scale


def test_check_still_fails_a_realisation_that_is_not_one(run_cli):
    """The spray series truncated at degree 3 is a birealisation only to O(p^4) (docs/theory.md
    §9): its axioms fail by about 1e-3, nine orders of magnitude above the tolerance."""
    status, out, err = run_cli("check", "nambu", "--realisation", "truncated:3", "--samples", "10")
    assert status == 1 and err.startswith("rkhp: check failed: nambu (truncated:3): birealisation axioms violated")
    assert "relative to the brackets' size, at most" in err and "FAILED" in out


# --------------------------------------------------------------------------- rkhp.integrate


def test_integrate_raises_on_a_failed_run():
    """A blow-up (docs/exit-status.md "Divergence"): rkhp.integrate raises NumericalFailure naming
    the step, as `rkhp integrate` exits 1; the failed trajectory travels with it, or is returned
    when asked for."""
    with pytest.raises(NumericalFailure, match="failed at step 5") as caught:
        rkhp.integrate("pendulum", "paper-three-stage", 1e5, 10)
    failed = caught.value.trajectory
    assert not failed.ok and failed.failed_step == 5 and len(failed.states) == 6
    kept = rkhp.integrate("pendulum", "paper-three-stage", 1e5, 10, allow_failure=True)
    assert not kept.ok and np.array_equal(kept.states, failed.states)
    assert rkhp.integrate("pendulum", "paper-three-stage", 0.1, 10).ok
