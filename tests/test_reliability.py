"""Nothing silently wrong, nothing lost, no wait without end (docs/exit-status.md, docs/input.md).

One section per class: interrupts, blow-ups, verdicts and tables, big numbers, implicit stages
where the sweeps stall, bounded waits, files, output, the Python API. The expected values come
from outside the code: observed drifting local orders ( 3.95, 3.92, 3.86, 3.74), the
oscillator's barrier of the paper's implicit method (z* = sqrt 3, docs/implicit.md "When the sweeps
stall"), the rigid body's exact solution, float64's range.
"""

from __future__ import annotations

import errno
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from child_signals import default_signals

import rkhp
from rkhp.base.errors import InputError, NumericalFailure
from rkhp.base.json_form import json_form

OSCILLATOR = ('name = "oscillator"\nfamily = "constant"\npoisson = [[0, 1], [-1, 0]]\n'
              'hamiltonian = "(x1^2 + x2^2)/2"\nx0 = [1, 0]\n')


def _spec(tmp_path, text: str, name: str = "spec.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# --------------------------------------------------------------------------- interrupts


def test_an_interrupt_inside_compiled_code_is_an_interrupt():
    """numba reports Ctrl-C inside a kernel as a SystemError raised from the KeyboardInterrupt."""
    from rkhp.base.interrupts import is_interrupt

    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher(...) returned a result with an exception set") from exc
    except SystemError as exc:
        assert is_interrupt(exc)
    assert not is_interrupt(ValueError("a failure"))


def test_interrupted_runs_keep_what_finished():
    from rkhp.base.executors import InProcess, run_until_interrupted
    from rkhp.base.interrupts import Interrupted

    def task(k):
        if k == 3:
            raise KeyboardInterrupt
        return k * k

    results, interrupted = run_until_interrupted(InProcess(), task, [(k,) for k in range(6)])
    assert interrupted and results == [0, 1, 4, None, None, None]

    def partial(k):
        if k == 1:
            raise Interrupted(["half of task 1"])
        return k

    results, interrupted = run_until_interrupted(InProcess(), partial, [(k,) for k in range(3)])
    assert interrupted and results == [0, ["half of task 1"], None]


def _interrupting(method, stop_steps: int):
    """The method, raising KeyboardInterrupt (as Ctrl-C would) on its run of `stop_steps` steps."""
    from dataclasses import dataclass

    from rkhp.integrators.methods import Method

    @dataclass(frozen=True)
    class Interrupting(Method):
        def integrate(self, system, h, n_steps, x0=None, *, keep_all=True):
            if n_steps == stop_steps:
                raise KeyboardInterrupt
            return super().integrate(system, h, n_steps, x0, keep_all=keep_all)

    return Interrupting(method.name, method.kind, method.tableau)


def test_converge_interrupted_keeps_the_rows_finished():
    from rkhp.integrators.methods import resolve_method
    from rkhp.studies.converge import converge

    method = _interrupting(resolve_method("rk4"), 160)
    study = converge("rigid-body", [method], steps=[20, 40, 80, 160, 320])
    assert study.interrupted and json_form(study)["interrupted"] is True
    assert [r.steps for r in study.methods[0].rows] == [20, 40, 80]
    assert study.methods[0].rows[2].local_order == pytest.approx(4.0, abs=0.2)  # RK4's order


def test_bench_interrupted_keeps_the_points_finished():
    from rkhp.integrators.methods import resolve_method
    from rkhp.studies.bench import bench

    method = _interrupting(resolve_method("rk4"), 40)
    study = bench("rigid-body", [method], peers=(), steps=(10, 20, 40, 80), repeats=1)
    assert study.interrupted
    assert [p.steps for p in study.curves[0].points] == [10, 20]


def test_stress_interrupted_keeps_the_parts_finished():
    from rkhp.integrators.methods import resolve_method
    from rkhp.studies.stress import NOT_RUN, stress

    method = _interrupting(resolve_method("rk4"), 1000)  # the long run of part (b)
    study = stress("rigid-body", [method], long_steps=1000, sweep_coarsest=8, round_off_steps=(32, 64, 128))
    assert study.interrupted and len(study.sweep) == 1
    assert study.long_run is None and study.round_off is None
    assert study.verdicts()["b"] == NOT_RUN and json_form(study)["long_run"] is None


def _handles_sigint(pid: int) -> bool:
    """Whether process `pid` has a handler for SIGINT (Linux: the SigCgt mask of /proc/PID/status;
    True where there is no /proc to ask)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("SigCgt:"):
                    return bool(int(line.split()[1], 16) >> (signal.SIGINT - 1) & 1)
    except OSError:
        return True
    return True


def _start_interruptible(args):
    """`python -m rkhp ARGS`, returned once the interpreter handles SIGINT: before, a Ctrl-C meets
    the default action of a process that is still starting (killed, status -2, no Python code
    run), which no program can answer. On a loaded machine that start alone can take 0.5 s."""
    proc = subprocess.Popen([sys.executable, "-m", "rkhp", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    deadline = time.monotonic() + 60
    while proc.poll() is None and not _handles_sigint(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.005)
    return proc


@pytest.mark.parametrize("delay", [0.5, 2.0, 4.0])
def test_ctrl_c_through_the_command_line(delay):
    """Ctrl-C at several moments of `rkhp converge` (counted from the interpreter's start): never a
    traceback, status 130 with one line (or the study finished first: status 0)."""
    proc = _start_interruptible(["converge", "pendulum", "--method", "euler", "--steps", "20",
                                 "--refinements", "16"])
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert "Traceback" not in err and "Error" not in err
    assert proc.returncode in (130, 0)
    if proc.returncode == 130:
        assert err.strip().splitlines() and err.strip().splitlines()[-1].startswith("rkhp: interrupted")
        assert len(err.strip().splitlines()) == 1


#: commands that run for seconds, each interrupted at 20 seeded random moments (imports and
#: compiled kernels included)
LONG_COMMANDS = {
    "integrate": ("integrate", "rigid-body", "--method", "paper-three-stage", "--steps", "2000000"),
    "converge": ("converge", "pendulum", "--method", "euler", "--steps", "20", "--refinements", "16"),
    "bench": ("bench", "pendulum", "--method", "rk4", "--repeats", "5"),
    "stress": ("stress", "pendulum", "--method", "rk4"),
    "search": ("search", "--stages", "4", "--order", "5", "--restarts", "1000", "--seed", "0"),
}


@pytest.mark.slow
@pytest.mark.parametrize("command", LONG_COMMANDS)
def test_ctrl_c_at_random_moments_is_never_a_traceback(command):
    """20 tries per command, Ctrl-C a random 0.5..4 s (seeded per command) after the interpreter
    handles SIGINT (`_start_interruptible`): status 130 with the one line `rkhp: interrupted` (or
    0: the command finished first), never a traceback."""
    import random

    moments = random.Random(f"ctrl-c {command}")
    outcomes = []
    for _ in range(20):
        delay = moments.uniform(0.5, 4.0)
        proc = _start_interruptible(LONG_COMMANDS[command])
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
        assert "Traceback" not in err, (delay, err[-3000:])
        assert proc.returncode in (130, 0), (delay, proc.returncode, err[-3000:])
        if proc.returncode:  # one line: "rkhp: interrupted", perhaps saying what is shown, after
            # the run's cost note when it has one (docs/methods.md)
            *before, last = err.splitlines()
            assert err.endswith("\n") and last.startswith("rkhp: interrupted"), (delay, err[-3000:])
            assert all(line.startswith("rkhp: note: ") for line in before), (delay, err[-3000:])
        outcomes.append(proc.returncode)
    assert 130 in outcomes  # the moments fall inside the run, not all after it


# --------------------------------------------------------------------------- blow-ups


def test_a_blow_up_is_a_numerical_failure_naming_the_step(run_cli):
    traj = rkhp.integrate("pendulum", "paper-three-stage", 1e5, 10, allow_failure=True)
    assert not traj.ok and traj.cause.name == "DIVERGED"
    assert traj.failed_step is not None and len(traj.states) == traj.failed_step + 1
    assert np.abs(traj.states).max() <= 100 * 1.5  # the kept states are before the blow-up
    status, out, err = run_cli("integrate", "pendulum", "--method", "paper-three-stage", "--steps", "10",
                               "--t-final", "1e6")
    assert status == 1 and err.count("\n") == 1 and "diverged" in err and "failed at step" in err


def test_growth_that_keeps_the_energy_is_no_divergence(tmp_path):
    """H = x1 x2 on the canonical plane: x1 grows like e^t (1.2e4 at T = 9.5), H is conserved."""
    spec = _spec(tmp_path, 'family = "constant"\npoisson = [[0, 1], [-1, 0]]\nhamiltonian = "x1*x2"\n'
                           'x0 = [1, 1]\n')
    traj = rkhp.integrate(str(spec), "rk4", 0.05, 190)
    assert traj.ok and traj.states[-1, 0] > 1e4


@pytest.mark.parametrize("bad, expected", [
    ((0, 0, math.inf), 0), ((3, 1, math.nan), 3), ((7, 1, -math.inf), 7),
    ((5, 1, 149.0), None),  # |y| at most GROWTH = 100 times |y_0| = 1.5: not grown
    ((5, 0, 1e9), None),  # q grown, H = p^2/2 - cos q still bounded: no divergence
    ((5, 1, 1e9), 5),  # p grown, H = 5e17: past DIVERGENCE = 1e8 times max(1, |H(y_0)|)
])
def test_divergence_follows_its_rule(bad, expected):
    """The rule of docs/exit-status.md "Divergence" on hand-made states (q, p) of the pendulum,
    H = p^2/2 - cos q: the first non-finite state, or the first grown state whose energy left
    every sane range."""
    from rkhp.integrators.trajectory import divergence

    system = rkhp.get_system("pendulum")
    states = np.full((10, 2), 0.5)
    states[0] = (1.5, 0.0)
    k, column, value = bad
    states[k, column] = value
    assert divergence(system, states) == expected


# --------------------------------------------------------------------------- verdicts and tables


def _errors_with_local_orders(orders, h0=0.1):
    h = [h0 / 2**k for k in range(len(orders) + 1)]
    e = [1e-3]
    for p in orders:
        e.append(e[-1] / 2**p)
    return h, e


def test_a_steady_fall_of_the_local_orders_is_not_a_higher_order():
    """Rows whose local orders fall steadily: 3.95, 3.92, 3.86, 3.74 (all in the fit), expected 3."""
    from rkhp.studies.fit import drift, fit_order, verdict

    h, e = _errors_with_local_orders([3.95, 3.92, 3.86, 3.74])
    fit = fit_order(h, e)
    assert fit.slope > 3.2 and drift(fit) == "falling"
    assert verdict(fit.slope, 3, fit) == "inconclusive"
    steady = fit_order(*_errors_with_local_orders([3.84, 3.85, 3.84, 3.85]))
    assert drift(steady) is None and verdict(steady.slope, 3, steady) == "higher than expected"
    rising = fit_order(*_errors_with_local_orders([2.6, 2.7, 2.75, 2.85]))  # towards 3: not yet there
    assert drift(rising) == "rising" and verdict(rising.slope, 3, rising) == "inconclusive"
    away = fit_order(*_errors_with_local_orders([2.6, 2.5, 2.45, 2.35]))  # away from 3: shown lower
    assert drift(away) == "falling" and verdict(away.slope, 3, away) == "lower than expected"


def test_no_casimir_is_a_dash_not_zero():
    from rkhp.studies.converge import converge

    study = converge("pendulum", ["rk4"], steps=[20, 40, 80], t_final=1.0)
    assert all(r.casimir_error is None for r in study.methods[0].rows)
    assert all(r["casimir_error_max"] is None for r in json_form(study)["methods"][0]["rows"])


def test_stress_counts_the_peer_once_and_not_as_rkhp():
    from rkhp.integrators.methods import resolve_methods
    from rkhp.studies.stress import long_run
    from rkhp.systems import get_system

    result = long_run(resolve_methods(["paper-three-stage", "classical:rk4"]), get_system("rigid-body"),
                      0.1, 200, 4)
    names = [r.method for r in (*result.runs, result.peer)]
    assert sorted(names) == ["classical:rk4", "paper-three-stage"]
    assert "1 of 1 RKHP methods" in result.verdict()


# --------------------------------------------------------------------------- big numbers


def test_a_310_digit_integer_is_refused_in_one_line(tmp_path):
    big = "1" + "0" * 310
    spec = _spec(tmp_path, f'family = "constant"\npoisson = [[0, 1], [-1, 0]]\n'
                           f'hamiltonian = "x1^2/2 + x2^2/2 + {big}*x1"\nx0 = [1, 0]\n')
    with pytest.raises(InputError):
        rkhp.get_system(str(spec))
    exact = _spec(tmp_path, f'family = "constant"\npoisson = [[0, 1], [-1, 0]]\n'
                            f'hamiltonian = "x1^2/2 + x2^2/2 + {big}*x1/{big}"\nx0 = [1, 0]\n', "exact.toml")
    assert rkhp.get_system(str(exact)).hamiltonian(np.array([1.0, 0.0])) == pytest.approx(1.5)


def test_entries_beyond_the_float_range():
    """1e400 cannot be a float64 (largest 1.8e308): exact verification reads it, float paths refuse it."""
    from rkhp.tableaux.tableau import Tableau

    tab = Tableau.from_arrays([["0", "0"], ["1e400", "0"]], ["1/2", "1/2"], name="huge")
    assert rkhp.verify(tab, precision="exact").orders["general"] == 1  # b c = 5e399 != 1/2
    with pytest.raises(InputError, match="beyond the float range"):
        rkhp.verify(tab, precision="float")
    with pytest.raises(InputError, match="beyond the float range"):
        rkhp.integrate("rigid-body", tab, 0.1, 2)


def test_float_verification_refuses_weights_that_overflow():
    from rkhp.tableaux.tableau import Tableau

    tab = Tableau.from_arrays([[0, 0], [1e300, 0]], [0.5, 0.5], name="e300")
    with pytest.raises(NumericalFailure, match="overflow"):
        rkhp.verify(tab, precision="float", max_order=4)
    assert rkhp.verify(tab, precision="exact", max_order=4).orders["general"] == 1


def test_a_2000_digit_rational_is_verified():
    n = 10**1999
    tab = rkhp.Tableau.from_arrays([[0, 0], [Fraction(1, 2), 0]], [0, 1], name="midpoint")
    long = rkhp.Tableau.from_arrays([[0, 0], [Fraction(n, 2 * n + 1), 0]], [0, 1], name="near-midpoint")
    assert rkhp.verify(tab).orders["general"] == 2
    assert rkhp.verify(long).orders["general"] == 1  # c2 = n/(2n+1) != 1/2 exactly


# --------------------------------------------------------------------------- implicit stages


@pytest.mark.parametrize("method", ["gauss2", "gauss3", "radau-iia3", "paper-implicit"])
def test_implicit_methods_take_h_1_on_the_rigid_body(method):
    """The sweeps do not contract at h = 1; Newton on the stage equations solves them."""
    traj = rkhp.integrate("rigid-body", method, 1.0, 10)
    assert traj.ok, traj.status
    system = rkhp.get_system("rigid-body")
    assert np.abs(traj.final_state - system.exact_solution(10.0)).max() < 1e-2
    casimir = system.casimirs[0]
    assert abs(casimir(traj.final_state) - casimir(traj.states[0])) < 1e-13


def test_implicit_stages_fail_only_past_the_oscillator_barrier(tmp_path):
    """The paper's implicit method (a = 1/sqrt 3) on the oscillator: its stage equation
    m = z a (1 + m^2/4) has a real solution exactly for z <= sqrt 3 = 1.732."""
    spec = str(_spec(tmp_path, OSCILLATOR))
    below = rkhp.integrate(spec, "paper-implicit", 1.7, 4)
    assert below.ok
    assert abs(below.states[-1] @ below.states[-1] - 1.0) < 1e-12  # a rotation: the amplitude is exact
    above = rkhp.integrate(spec, "paper-implicit", 1.76, 4, allow_failure=True)
    assert not above.ok and above.failed_step == 0


# --------------------------------------------------------------------------- waits


def test_scheduler_addresses_need_a_port():
    from rkhp.base.executors import check_scheduler

    for bad in ("tcp://127.0.0.1", "http://127.0.0.1:8786", "tcp://host:0", "host:99999"):
        with pytest.raises(InputError, match="with a port"):
            check_scheduler(bad)
    assert check_scheduler(" tls://[::1]:8786 ") == "tls://[::1]:8786"


def test_a_server_that_never_answers_is_one_line_within_the_bound():
    pytest.importorskip("distributed")
    from rkhp.base.executors import DaskCluster

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    accepted = []
    threading.Thread(target=lambda: accepted.append(server.accept()), daemon=True).start()
    t0 = time.monotonic()
    with pytest.raises(InputError):
        DaskCluster(f"tcp://127.0.0.1:{server.getsockname()[1]}", connect_seconds=1.0)
    assert time.monotonic() - t0 < 10.0
    server.close()


def test_search_time_limit_holds_for_the_whole_search():
    import scipy.optimize  # noqa: F401 - imported before the clock starts (seconds on a cold start)

    from rkhp.search.driver import SearchOptions, search

    t0 = time.perf_counter()
    result = search(6, None, options=SearchOptions(restarts=10**6, time_limit=2.0))
    assert time.perf_counter() - t0 < 2.0 + 6.0  # plus the verification of an order found at the end
    assert result.runs  # what was found within the limit is kept


# --------------------------------------------------------------------------- files


def test_files_are_never_replaced_silently(tmp_path):
    from rkhp.base.files import write_atomic

    target = tmp_path / "out.json"
    target.write_text("precious")
    with pytest.raises(InputError, match="exists"):
        write_atomic(target, "new")
    assert target.read_text() == "precious"
    write_atomic(target, "new", force=True)
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_a_symbolic_link_is_never_followed(tmp_path):
    from rkhp.base.files import write_atomic

    victim = tmp_path / "spec.toml"
    victim.write_text("spec")
    link = tmp_path / "link.toml"
    link.symlink_to(victim)
    with pytest.raises(InputError, match="symbolic link"):
        write_atomic(link, "tableau")
    write_atomic(link, "tableau", force=True)
    assert victim.read_text() == "spec" and not link.is_symlink() and link.read_text() == "tableau"


def test_a_full_disk_leaves_nothing_behind(tmp_path, monkeypatch):
    from rkhp.base import files
    from rkhp.base.errors import WriteFailed

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(files.os, "fsync", full)
    with pytest.raises(WriteFailed, match="No space left"):
        files.write_atomic(tmp_path / "t.toml", "A = [[0]]\n")
    assert list(tmp_path.iterdir()) == []


def test_save_refuses_an_existing_file_before_the_work(tmp_path, run_cli):
    spec = tmp_path / "spec.toml"
    spec.write_text(OSCILLATOR)
    status, out, err = run_cli("search", "--stages", "2", "--order", "2", "--save", str(spec))
    assert status == 2 and "exists" in err and err.count("\n") == 1
    assert spec.read_text() == OSCILLATOR


# --------------------------------------------------------------------------- output


def test_stdout_on_a_full_device_is_one_line(tmp_path):
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "rkhp", "systems"], stdout=full, stderr=subprocess.PIPE,
                              text=True, timeout=60)
    assert proc.returncode == 1 and proc.stderr.count("\n") == 1
    assert "No space left" in proc.stderr and "Traceback" not in proc.stderr


def test_text_from_files_is_not_markup_nor_control(tmp_path, run_cli):
    name = "[bold red]x[/bold red][/]\\nrkhp: error: fake"
    spec = _spec(tmp_path, OSCILLATOR.replace('name = "oscillator"', f'name = "{name}"'))
    status, out, err = run_cli("integrate", str(spec), "--method", "rk4", "--steps", "4")
    assert status == 0 and err == ""
    assert "[bold red]x[/bold red][/]" in out
    assert not any(line.startswith("rkhp: error") for line in out.splitlines())


def test_printable_escapes_control_characters():
    from rkhp_cli.terminal import plain, printable

    assert printable("a\nb\x1b[2Jc\u202e") == "a\\nb\\x1b[2Jc\\u202e"
    assert plain("[/]") == "\\[/]"


# --------------------------------------------------------------------------- the Python API


@pytest.mark.parametrize("x0", [["1", "0", "0"], {"x1": 1}, [1 + 2j, 0, 0], [[1, 0, 0]], [math.nan, 0, 0], "1,0,0"])
def test_api_x0_is_checked(x0):
    with pytest.raises(InputError):
        rkhp.integrate("rigid-body", "rk4", 0.1, 10, x0=x0)


@pytest.mark.parametrize("h, n", [("0.1", 10), (True, 10), (0.1, True), (0.1, 2.5), (0.1, "10"), (math.inf, 10)])
def test_api_steps_are_checked(h, n):
    with pytest.raises(InputError):
        rkhp.integrate("rigid-body", "rk4", h, n)


def test_api_memory_bound():
    with pytest.raises(InputError, match="memory"):
        rkhp.integrate("rigid-body", "rk4", 0.1, 10**9)


def test_api_tableau_from_plain_numbers():
    tab = rkhp.Tableau("rk2", [[0, 0], [0.5, 0]], [0, 1])
    assert tab.A[1][0] == Fraction(1, 2) and rkhp.verify(tab).orders["general"] == 2
    with pytest.raises(InputError):
        rkhp.Tableau("bad", [[0, 0], ["x", 0]], [0, 1])


def test_ctrl_c_stops_a_compile_in_several_processes_at_once(tmp_path):
    """Ctrl-C on a terminal (SIGINT to the whole process group) during `rkhp compile --jobs 2` on
    an empty cache: status 130 and one line within seconds, not after the running compiles, and
    no process of the group left."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    proc = subprocess.Popen([sys.executable, "-m", "rkhp", "compile", "--jobs", "2"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=default_signals)
    deadline = time.monotonic() + 60
    while proc.poll() is None and len(_children(proc.pid)) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(2.0)  # both compiling
    assert proc.poll() is None
    os.killpg(proc.pid, signal.SIGINT)
    start = time.monotonic()
    out, err = proc.communicate(timeout=60)
    assert time.monotonic() - start < 10
    assert proc.returncode == 130 and err.strip().splitlines() == ["rkhp: interrupted"], err
    time.sleep(0.5)
    with pytest.raises(ProcessLookupError):
        os.killpg(proc.pid, 0)


def _children(pid: int) -> list[int]:
    """The child processes of ``pid`` (Linux: /proc/PID/task/*/children)."""
    found = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        found += [int(c) for c in task.read_text().split()]
    return found
