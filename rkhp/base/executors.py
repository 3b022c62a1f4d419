"""Executors: where the independent tasks of a search, a study or an ensemble run (docs/distributed.md).

One interface, three implementations; the library's loops (restarts, convergence rows, primes of a
relation derivation, chunks of an ensemble) are written once against :class:`Executor` and do not
know which one runs them:

- :class:`InProcess`: in this process, one task at a time, lazily (a task runs when its result is
  waited for, so a task cancelled before then never runs);
- :class:`LocalProcesses`: a pool of ``workers`` processes on this machine (``--workers N``);
- :class:`DaskCluster`: the workers of a Dask scheduler (``--scheduler ADDRESS`` or
  ``$DASK_SCHEDULER_ADDRESS``); Dask retries the tasks of a lost worker on another one.

Every task is a pure function of its arguments (seeds travel with the task), and the loops reduce
results in task order, never in completion order, so a result never depends on the executor, on
the number of workers or on a lost worker (only the wall time does). Dask and distributed are
imported only when a scheduler is used.
"""

from __future__ import annotations

import asyncio
import ctypes
import json
import logging
import multiprocessing
import os
import pickle
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import closing, contextmanager
from pathlib import Path
from typing import Any, Protocol

from .errors import ClusterLost, InputError
from .interrupts import is_interrupt

#: The environment variable Dask itself reads for the scheduler's address.
SCHEDULER_VARIABLE = "DASK_SCHEDULER_ADDRESS"
#: Seconds allowed to reach a scheduler before giving up with one line.
CONNECT_SECONDS = 10
#: Seconds a Dask cluster may be without workers (at the start, or during a run) before the
#: command ends with one line: its tasks would never run.
WORKERS_SECONDS = 30
#: How often a Dask executor looks for finished tasks while none is ready (seconds).
POLL_SECONDS = 0.01
#: How often a Dask executor asks the scheduler how many worker threads it has (seconds).
SLOTS_SECONDS = 5.0
#: Seconds a Dask client may take to close (a scheduler that is gone does not answer).
CLOSE_SECONDS = 2
#: Largest --workers accepted (a local pool; a larger run belongs on a cluster).
MAX_LOCAL_WORKERS = 256
_ADDRESS = re.compile(r"((tcp|tls|ws|wss|ucx)://)?(\[[0-9A-Fa-f:.]{2,60}\]|[A-Za-z0-9_.\-]{1,200}):([0-9]{1,5})")


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the platform tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


class Task(Protocol):
    """A submitted task: its result (re-raising the task's exception) and whether it finished."""

    def result(self) -> Any: ...

    def done(self) -> bool: ...


class Executor(Protocol):
    """Runs independent tasks. ``kind``: "in-process", "processes" or "dask"; ``slots``: how many
    tasks run at once (the loops keep about twice that many submitted)."""

    kind: str
    slots: int

    def submit(self, fn: Callable, /, *args) -> Task:
        """Start ``fn(*args)`` (arguments and result are pickled, except in-process)."""

    def as_completed(self, tasks: Iterable[Task]) -> Iterator[Task]:
        """The tasks, each as it finishes."""

    def cancel(self, tasks: Iterable[Task]) -> None:
        """Cancel tasks not finished yet (on a cluster: removed from the scheduler)."""

    def close(self) -> None:
        """Release the workers (a Dask cluster itself keeps running)."""

    def terminate(self) -> None:
        """Stop the tasks now, running ones included (local workers are killed): after an
        interrupt, whose unfinished tasks' results are not used."""


def first_done(executor: Executor, tasks: Iterable[Task]) -> Task:
    """The first of ``tasks`` to finish (waits for it)."""
    with closing(executor.as_completed(tasks)) as stream:
        return next(iter(stream))


def run_all(executor: Executor, fn: Callable, argument_tuples: Iterable[tuple], on_done=None) -> list:
    """``[fn(*args) for args in argument_tuples]`` on the executor, results in the given order;
    ``on_done(done, total)`` after each completion (progress from the workers' finished tasks).
    On an error or Ctrl-C the unfinished tasks are cancelled and the exception goes on."""
    results, finished = _gather(executor, fn, argument_tuples, on_done, keep_on_interrupt=False)
    return results


def run_until_interrupted(executor: Executor, fn: Callable, argument_tuples: Iterable[tuple],
                          on_done=None) -> tuple[list, bool]:
    """As :func:`run_all`, but an interrupt (`rkhp.base.interrupts.is_interrupt`) cancels the
    unfinished tasks and returns what finished: (results in the given order, None where a task did
    not finish; whether the run was interrupted)."""
    return _gather(executor, fn, argument_tuples, on_done, keep_on_interrupt=True)


def _gather(executor, fn, argument_tuples, on_done, keep_on_interrupt: bool) -> tuple[list, bool]:
    tasks = [executor.submit(fn, *args) for args in argument_tuples]
    order = {id(t): k for k, t in enumerate(tasks)}
    results: list = [None] * len(tasks)
    try:
        for count, task in enumerate(executor.as_completed(tasks), start=1):
            results[order[id(task)]] = task.result()
            if on_done is not None:
                on_done(count, len(tasks))
    except BaseException as exc:
        executor.cancel(tasks)
        if is_interrupt(exc):
            executor.terminate()  # the running tasks' results would not be used
        if keep_on_interrupt and is_interrupt(exc):
            partial = getattr(exc, "partial", None)
            running = next((k for k, t in enumerate(tasks) if not t.done()), None)
            if partial is not None and executor.kind == "in-process" and running is not None:
                results[running] = partial  # the task that was running here, as far as it got
            return results, True
        raise
    return results, False


# ----------------------------------------------------------------------------- in this process


class _Deferred:
    """An in-process task, run when it is first waited for."""

    def __init__(self, fn, args):
        self._call = (fn, args)
        self._outcome = None

    def done(self) -> bool:
        return self._outcome is not None

    def cancelled(self) -> bool:
        return self._call is None and self._outcome is None

    def cancel(self) -> None:
        if self._outcome is None:
            self._call = None

    def run(self) -> None:
        """Compute the outcome once (an exception is kept and re-raised by :meth:`result`)."""
        if self._outcome is None and self._call is not None:
            fn, args = self._call
            try:
                self._outcome = (True, fn(*args))
            except Exception as exc:
                self._outcome = (False, exc)

    def result(self):
        if self.cancelled():
            raise InputError("the task was cancelled")
        self.run()
        ok, value = self._outcome
        if not ok:
            raise value
        return value


class InProcess:
    """Tasks run one after another in this process, in submission order."""

    kind = "in-process"
    slots = 1

    def submit(self, fn, /, *args) -> _Deferred:
        return _Deferred(fn, args)

    def as_completed(self, tasks):
        for task in list(tasks):
            if not task.cancelled():
                task.run()
                yield task

    def cancel(self, tasks) -> None:
        for task in tasks:
            task.cancel()

    def close(self) -> None:
        pass

    def terminate(self) -> None:
        pass


# ----------------------------------------------------------------------------- processes on this machine


#: Linux's prctl option that sets the signal a process receives when its parent ends
PR_SET_PDEATHSIG = 1
#: how often a worker without the parent-death signal looks whether its parent has ended (seconds)
PARENT_WATCH_SECONDS = 1.0


def die_with_parent(parent: int) -> None:
    """This process (a worker forked by ``parent``) is killed when its parent ends, however the
    parent ends (SIGKILL included): on Linux by the parent-death signal (prctl PR_SET_PDEATHSIG,
    SIGKILL), elsewhere by a thread that looks every PARENT_WATCH_SECONDS whether the parent is
    still its parent. A parent that ended before this was set: the process ends now."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            armed = libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
        if armed:
            if os.getppid() != parent:
                os._exit(1)
            return
    threading.Thread(target=_watch_parent, args=(parent,), name="rkhp-parent-watch", daemon=True).start()


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_WATCH_SECONDS)
    os._exit(1)


def _start_worker(parent: int) -> None:
    """A pool worker's start: Ctrl-C left to the parent, which cancels and reports; SIGTERM and
    SIGHUP at their default action (the fork copied the command's handlers, which would turn the
    pool's SIGTERM into a task's exception); ended with its parent (`die_with_parent`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    die_with_parent(parent)


def _call_pickled(payload: bytes):
    fn, args = pickle.loads(payload)
    return fn(*args)


class LocalProcesses:
    """A pool of ``workers`` forked processes. Tasks travel by cloudpickle (systems hold closures)."""

    kind = "processes"

    def __init__(self, workers: int):
        self.slots = workers
        self._pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                                         initializer=_start_worker, initargs=(os.getpid(),))

    def submit(self, fn, /, *args):
        import cloudpickle

        return self._pool.submit(_call_pickled, cloudpickle.dumps((fn, args)))

    def as_completed(self, tasks):
        return as_completed(list(tasks))

    def cancel(self, tasks) -> None:
        for task in tasks:
            task.cancel()

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)

    def terminate(self) -> None:
        """Stop the workers now, running tasks included (their results are lost): for tasks whose
        partial work is worth nothing, after an interrupt or an error."""
        stop = getattr(self._pool, "terminate_workers", None)  # Python 3.14
        if stop is not None:
            stop()
            return
        for process in list((getattr(self._pool, "_processes", None) or {}).values()):
            process.terminate()
        self._pool.shutdown(wait=True, cancel_futures=True)


# ----------------------------------------------------------------------------- a Dask cluster


#: the package whose loggers an open `DaskCluster` silences: their errors reach the caller as
#: rkhp's exceptions (a lost scheduler is one ClusterLost, not distributed's reconnection tracebacks)
DASK_LOGGERS = "distributed"


class _QuietLogs:
    """distributed's loggers (`DASK_LOGGERS` and those below it, which Dask's configuration gives
    levels of their own) silenced, and their levels put back by `restore`."""

    def __init__(self):
        names = [name for name in list(logging.root.manager.loggerDict)
                 if name == DASK_LOGGERS or name.startswith(DASK_LOGGERS + ".")]
        self._levels = [(logging.getLogger(name), logging.getLogger(name).level) for name in [DASK_LOGGERS, *names]]
        for logger, _ in self._levels:
            logger.setLevel(logging.CRITICAL + 1)

    def restore(self) -> None:
        for logger, level in self._levels:
            logger.setLevel(level)


class DaskCluster:
    """The workers of the Dask scheduler at ``address``; ``slots`` = their threads. While it is
    open, distributed's own log lines are silenced: what goes wrong reaches the caller as one
    exception (InputError for a scheduler that cannot be used, ClusterLost for one lost during a
    run)."""

    kind = "dask"

    def __init__(self, address: str, connect_seconds: float = CONNECT_SECONDS,
                 workers_seconds: float = WORKERS_SECONDS):
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise InputError("--scheduler needs Dask: pip install 'rkhp[distributed]'") from None
        self._quiet = _QuietLogs()
        try:
            self._client = _connect(address, connect_seconds)
        except BaseException:
            self._quiet.restore()
            raise
        self.address = address
        self.workers_seconds = workers_seconds
        self._slots = (0.0, 1)
        self._wait_for_workers()

    def _wait_for_workers(self) -> None:
        """At least one worker within workers_seconds, else InputError (a scheduler without workers
        would run nothing and the command would wait for ever)."""
        deadline = time.monotonic() + self.workers_seconds
        while not self._worker_count():
            if time.monotonic() > deadline:
                self.close()
                raise InputError(f"the Dask scheduler at {self.address} has no workers (waited "
                                 f"{self.workers_seconds:g} s; start some with `dask worker {self.address}`)")
            time.sleep(0.2)

    def _worker_count(self) -> int:
        try:
            return len(self._client.scheduler_info(n_workers=-1).get("workers", {}))
        except TypeError:  # older distributed: no n_workers argument
            return len(self._client.scheduler_info().get("workers", {}))
        except Exception as exc:  # noqa: BLE001 - the scheduler went away: one line
            raise InputError(f"lost the Dask scheduler at {self.address} ({type(exc).__name__})") from None

    @property
    def slots(self) -> int:
        """The workers' threads now (asked of the scheduler at most every SLOTS_SECONDS, so that
        workers joining or leaving during a run change how many tasks are kept submitted)."""
        asked, count = self._slots
        if time.monotonic() - asked > SLOTS_SECONDS:
            count = max(1, sum(self._client.nthreads().values()))
            self._slots = (time.monotonic(), count)
        return count

    def submit(self, fn, /, *args):
        return self._client.submit(fn, *args, pure=False)

    def as_completed(self, tasks):
        """The tasks as they finish; InputError when the cluster has had no worker for
        workers_seconds (nothing would ever finish), ClusterLost when a task was cancelled by
        anyone but this executor (distributed cancels every task of a client that lost its
        scheduler). Polls distributed's stream every POLL_SECONDS and the workers every second."""
        from distributed import as_completed

        stream = as_completed(list(tasks), loop=self._client.loop)
        idle_since = None
        checked = time.monotonic()
        while not stream.is_empty():
            batch = stream.next_batch(block=False)
            if batch:
                idle_since = None
                for task in batch:
                    if task.cancelled():
                        raise self._lost(task)
                    yield task
                continue
            time.sleep(POLL_SECONDS)
            now = time.monotonic()
            if now - checked < 1.0:
                continue
            checked = now
            if self._worker_count():
                idle_since = None
            elif idle_since is None:
                idle_since = now
            elif now - idle_since > self.workers_seconds:
                raise InputError(f"the Dask cluster at {self.address} has had no workers for "
                                 f"{self.workers_seconds:g} s: its tasks cannot run")

    def _lost(self, task) -> ClusterLost:
        """The ClusterLost of a task cancelled under this executor, with distributed's reason when
        it gave one (``scheduler-connection-lost`` for a scheduler gone)."""
        cancelled = getattr(getattr(task, "_state", None), "exception", None)  # a FutureCancelledError
        reason = getattr(cancelled, "reason", None)
        said = f" ({reason})" if reason and reason != "unknown" else ""
        return ClusterLost(f"lost the Dask scheduler at {self.address} during the run: its tasks were "
                           f"cancelled{said}; the tasks not finished cannot be had")

    def cancel(self, tasks) -> None:
        if self._client.status != "running":  # a lost scheduler: nothing to tell it
            return
        tasks = [t for t in tasks if not t.done()]
        if tasks:
            self._client.cancel(tasks)

    def close(self) -> None:
        """The client closed (without waiting for a scheduler that is gone), distributed's log
        levels put back."""
        try:
            self._client.close(timeout=CLOSE_SECONDS)
        except Exception:  # noqa: BLE001 - a scheduler gone: the client is closed all the same
            pass
        finally:
            self._quiet.restore()

    def terminate(self) -> None:
        """Nothing beyond `cancel`: the scheduler stops cancelled tasks on its workers."""


#: getaddrinfo's answers that a host name has no address (not a resolver that failed for now)
_NO_SUCH_HOST = {getattr(socket, name) for name in ("EAI_NONAME", "EAI_NODATA") if hasattr(socket, name)}


def _refuse_early(address: str, seconds: float) -> None:
    """ConnectionRefusedError when the scheduler's host refuses a TCP connection to its port
    (nothing listens there), socket.gaierror when the resolver answers that the host name has no
    address (`_NO_SUCH_HOST`): failures that Dask's client would retry until its timeout. Nothing
    when the connection opens (the scheduler logs a connection closed before its handshake) or
    fails otherwise, or after a fifth of ``seconds`` (Dask's own connection then says what it
    finds). Schemes over TCP only (not ucx)."""
    match = _ADDRESS.fullmatch(address)
    if match is None or match.group(2) == "ucx":
        return
    try:
        with socket.create_connection((match.group(3).strip("[]"), int(match.group(4))), timeout=seconds / 5):
            return
    except ConnectionRefusedError:
        raise
    except socket.gaierror as exc:
        if exc.errno in _NO_SUCH_HOST:
            raise
    except OSError:
        return


class NotAScheduler(Exception):
    """The server at a scheduler's address answered, but not as a Dask scheduler."""


def _identity(address: str, seconds: float) -> dict:
    """What the server at ``address`` says it is (distributed's ``identity`` operation), over one
    connection of Dask's protocol (with the security settings of Dask's configuration, as a
    Client's); NotAScheduler when it does not speak that protocol (an HTTP server, a dashboard:
    its answer read as Dask's frames is nonsense, such as a frame of exabytes)."""
    from distributed.comm import connect
    from distributed.security import Security

    async def ask():
        comm = await connect(address, timeout=seconds, **Security().get_connection_args("client"))
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    try:
        answer = asyncio.run(asyncio.wait_for(ask(), seconds))
    except (TimeoutError, OSError):
        raise
    except Exception as exc:  # noqa: BLE001 - frames that are not Dask's: any error of decoding them
        raise NotAScheduler(f"it does not speak Dask's protocol ({type(exc).__name__})") from None
    if not isinstance(answer, dict) or answer.get("type") != "Scheduler":
        kind = answer.get("type") if isinstance(answer, dict) else None
        raise NotAScheduler(f"it is a Dask {kind}, not a scheduler" if isinstance(kind, str)
                            else "its answer is not a Dask scheduler's")
    return answer


def _connect(address: str, seconds: float):
    """A distributed Client of the scheduler at ``address``, or InputError in one line within
    about ``seconds``: an address Dask cannot use (no port, an unknown scheme), an unknown host, a
    refused or unanswered connection (an unknown host or a refused connection at once:
    `_refuse_early`), a server that is not a Dask scheduler (asked first: `_identity`, so that no
    Client is made of it). The connection runs in a thread that is abandoned if it has not
    answered after 1.5 ``seconds`` (some failures never answer: a server that accepts and is
    silent)."""
    from distributed import Client

    outcome: dict = {}

    def connect():
        try:
            _refuse_early(address, seconds)
            _identity(address, seconds)
            outcome["client"] = Client(address, timeout=seconds, set_as_default=False)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller as one line
            outcome["error"] = exc

    thread = threading.Thread(target=connect, name="rkhp-dask-connect", daemon=True)
    thread.start()
    thread.join(1.5 * seconds)  # distributed's own timeout, then half as long again
    if thread.is_alive():
        raise InputError(f"no answer from a Dask scheduler at {address} within {seconds:g} s")
    error = outcome.get("error")
    if error is not None:
        if isinstance(error, KeyboardInterrupt):
            raise error
        if isinstance(error, NotAScheduler):
            raise InputError(f"the server at {address} is not a Dask scheduler: {error} (a scheduler "
                             "listens on port 8786 by default; 8787 is its dashboard)") from None
        if isinstance(error, ConnectionRefusedError):
            raise InputError(f"cannot reach the Dask scheduler at {address}: connection refused "
                             "(nothing listens on that port)") from None
        if isinstance(error, socket.gaierror) and error.errno in _NO_SUCH_HOST:
            raise InputError(f"cannot reach the Dask scheduler at {address}: unknown host "
                             "(the name has no address)") from None
        if isinstance(error, (OSError, TimeoutError)):
            raise InputError(f"cannot reach the Dask scheduler at {address} within {seconds:g} s "
                             f"({type(error).__name__})") from None
        detail = " ".join(str(error).split())[:120]
        raise InputError(f"cannot use the Dask scheduler at {address} ({type(error).__name__}"
                         + (f": {detail}" if detail else "") + ")") from None
    return outcome["client"]


# ----------------------------------------------------------------------------- choosing one


def check_scheduler(address: str, source: str = "--scheduler") -> str:
    """A scheduler address (``tcp://host:port``, ``host:port``, ``tls://[::1]:8786``: a scheme Dask
    connects with, a host and a port 1..65535), stripped; InputError otherwise."""
    text = str(address).strip()
    match = _ADDRESS.fullmatch(text)
    if not match or not 1 <= int(match.group(4)) <= 65535:
        raise InputError(f"{source} must be a Dask scheduler address with a port, such as tcp://host:8786, "
                         f"got {address!r}")
    return text


def check_workers(workers) -> int:
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= MAX_LOCAL_WORKERS:
        raise InputError(f"--workers must be an integer between 1 and {MAX_LOCAL_WORKERS}, got {workers!r}")
    return workers


def scheduler_address(workers: int = 1, scheduler: str | None = None, environ=None) -> str | None:
    """The scheduler to use: ``scheduler``, else ``$DASK_SCHEDULER_ADDRESS`` unless ``workers`` > 1
    asks for local processes; None for a run on this machine. Both given: InputError."""
    check_workers(workers)
    if scheduler is not None:
        if workers > 1:
            raise InputError("give --workers N (processes on this machine) or --scheduler ADDRESS (a Dask "
                             "cluster), not both")
        return check_scheduler(scheduler)
    env = (os.environ if environ is None else environ).get(SCHEDULER_VARIABLE, "").strip()
    if env and workers == 1:
        return check_scheduler(env, f"${SCHEDULER_VARIABLE}")
    return None


def make_executor(workers: int = 1, scheduler: str | None = None, environ=None) -> Executor:
    """The executor for ``--workers`` / ``--scheduler`` (see :func:`scheduler_address`)."""
    address = scheduler_address(workers, scheduler, environ)
    if address is not None:
        return DaskCluster(address)
    return LocalProcesses(workers) if workers > 1 else InProcess()


@contextmanager
def open_executor(workers: int = 1, scheduler: str | None = None, environ=None):
    """``with open_executor(workers, scheduler) as ex:`` the executor, closed afterwards."""
    executor = make_executor(workers, scheduler, environ)
    try:
        yield executor
    except BaseException as exc:
        if is_interrupt(exc):
            executor.terminate()  # not waiting for the running tasks
        raise
    finally:
        executor.close()


# ----------------------------------------------------------------------------- a cluster on this machine


class LoopbackCluster:
    """A Dask scheduler and workers started as processes on 127.0.0.1 (see :func:`loopback_cluster`).

    Attributes:
        address: the scheduler's address (give it to ``--scheduler``).
        workers: the worker processes (subprocess.Popen), e.g. to stop one.
        scheduler: the scheduler's process (subprocess.Popen), e.g. to kill it during a run.
    """

    def __init__(self, address: str, workers: list, scheduler=None):
        self.address = address
        self.workers = workers
        self.scheduler = scheduler


#: how long a process of `loopback_cluster` may take to stop once terminated before it is killed
#: (a worker whose scheduler has gone keeps reconnecting past SIGTERM)
STOP_SECONDS = 3


@contextmanager
def loopback_cluster(workers: int = 2, threads: int = 1, start_seconds: float = 120):
    """``with loopback_cluster(2) as cluster:`` a scheduler and ``workers`` single-process workers
    of ``threads`` threads each, started with ``dask scheduler`` / ``dask worker`` and bound to the
    loopback address only; all stopped afterwards. For the tests and benchmarks/distributed.py:
    a real cluster is started the same way on its machines (docs/distributed.md)."""
    dask = [sys.executable, "-m", "dask"]
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    procs: list = []
    with tempfile.TemporaryDirectory(prefix="rkhp-dask-") as tmp:
        info = Path(tmp) / "scheduler.json"
        try:
            loopback = ["--host", "127.0.0.1", "--dashboard-address", "127.0.0.1:0"]
            procs.append(subprocess.Popen([*dask, "scheduler", *loopback, "--port", "0", "--scheduler-file", str(info)],
                                          **quiet))
            deadline = time.monotonic() + start_seconds
            address = None
            while address is None:
                if procs[0].poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError("the Dask scheduler did not start")
                time.sleep(0.1)
                try:
                    address = json.loads(info.read_text())["address"]
                except (OSError, ValueError, KeyError):
                    address = None
            pool = [subprocess.Popen([*dask, "worker", address, *loopback, "--nthreads", str(threads),
                                      "--no-nanny", "--name", f"loopback-{k}",
                                      "--local-directory", tmp], **quiet)
                    for k in range(workers)]
            procs.extend(pool)
            from distributed import Client

            with Client(address, timeout=start_seconds, set_as_default=False) as client:
                client.wait_for_workers(workers, timeout=start_seconds)
            yield LoopbackCluster(address, pool, procs[0])
        finally:
            for proc in reversed(procs):
                proc.terminate()
            for proc in procs:
                try:
                    proc.wait(timeout=STOP_SECONDS)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
