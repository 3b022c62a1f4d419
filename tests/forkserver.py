"""A fork server for the hostile corpus (tests/test_hostile.py): each case in a process of its own,
without paying Python's start-up and rkhp's imports again for each.

Run as ``python tests/forkserver.py``: it imports the command line and the modules every command
needs (no numba: a case that reaches the engine imports it as a fresh process would), then reads
one JSON request per line on stdin and answers one JSON line on stdout. Each request is a case:
the server forks; the child starts a session of its own, enters the case's folder, takes the
case's environment, stdin from /dev/null, stdout and stderr into the files named, the resource
limits named, and runs ``rkhp ARGS`` as ``python -m rkhp`` would (an uncaught exception prints
its traceback, exit status 1); the server waits for it (killing its session at the wall limit)
and answers its exit status, wall and CPU seconds and peak memory.
"""

from __future__ import annotations

import importlib
import json
import os
import resource
import signal
import sys
import time

#: what every command imports before its work starts: loaded once, here
PRELOAD = ("click", "rich.console", "rich.table", "numpy", "sympy", "rkhp", "rkhp.systems",
           "rkhp.tableaux.files", "rkhp.base.expressions", "rkhp.integrators.methods")


def preload() -> None:
    from rkhp_cli.main import COMMANDS

    for name in PRELOAD + tuple(module for module, _, _ in COMMANDS.values()):
        importlib.import_module(name)


def child(request: dict) -> None:
    """The case's process: never returns (exits with the command's status)."""
    os.setsid()
    if ANSWERS is not None:
        ANSWERS.close()
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    for fd, path, flags in ((0, os.devnull, os.O_RDONLY), (1, request["stdout"], os.O_WRONLY | os.O_TRUNC),
                            (2, request["stderr"], os.O_WRONLY | os.O_TRUNC)):
        opened = os.open(path, flags)
        os.dup2(opened, fd)
        os.close(opened)
    sys.stdin = open(0, closefd=False)  # not the server's buffered requests
    space, cpu = request["address_space"], request["cpu_seconds"]
    resource.setrlimit(resource.RLIMIT_AS, (space, space))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
    sys.argv = [sys.executable, *request["args"]]
    from rkhp_cli.main import main

    main()  # its SystemExit (or an uncaught exception) ends the child as it ends `python -m rkhp`
    raise SystemExit(0)


def _leave(code) -> None:
    """End the case's process as `sys.exit(code)` would, without the interpreter's finalization
    (the server's modules: a fifth of a second per case); the session is killed after it anyway."""
    if code is not None and not isinstance(code, int):
        print(code, file=sys.stderr)
        code = 1
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:
            pass
    os._exit(code or 0)


def serve(request: dict) -> dict:
    start = time.perf_counter()
    pid = os.fork()
    if pid == 0:
        try:
            child(request)
        except SystemExit as exc:
            _leave(exc.code)
        except BaseException:
            import traceback

            traceback.print_exc()
            _leave(1)
    deadline = start + request["wall_seconds"]
    while True:
        done, code, usage = os.wait4(pid, os.WNOHANG)
        if done:
            break
        if time.perf_counter() > deadline:
            os.killpg(pid, signal.SIGKILL)
            _, code, usage = os.wait4(pid, 0)
            break
        time.sleep(0.002)
    wall = time.perf_counter() - start
    try:  # what the case's process left behind (its session: workers it forked)
        os.killpg(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    return {"status": "timeout" if wall >= request["wall_seconds"] else os.waitstatus_to_exitcode(code),
            "wall": wall, "cpu": usage.ru_utime + usage.ru_stime, "rss": usage.ru_maxrss * 1024}


#: the server's answers (a copy of its stdout, so that a case's stdout can take fd 1)
ANSWERS = None


def main() -> None:
    global ANSWERS
    preload()
    ANSWERS = os.fdopen(os.dup(1), "w", buffering=1)
    print(json.dumps({"ready": True}), file=ANSWERS)
    for line in sys.stdin:
        print(json.dumps(serve(json.loads(line))), file=ANSWERS)


if __name__ == "__main__":
    main()
