"""Searches, studies and ensembles on a Dask cluster (docs/distributed.md).

The reference values are the single-process runs with the same seed: a restart, a convergence row
or a chunk of an ensemble is a pure function of its arguments, so the cluster must give the same
numbers bit for bit, and a worker killed mid-search must change nothing (Dask reruns its tasks).
The cluster is a real one: `dask scheduler` and two `dask worker` processes on 127.0.0.1.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

from rkhp.base.errors import InputError
from rkhp.base.executors import loopback_cluster, open_executor, scheduler_address
from rkhp.base.json_form import json_form

pytest.importorskip("distributed", reason="the distributed tests need rkhp[distributed] (make test installs it)")


def _rkhp(*args, env=None):
    proc = subprocess.run([sys.executable, "-m", "rkhp", *args], capture_output=True, text=True, timeout=300,
                          env={**os.environ, **(env or {})})
    return proc.returncode, proc.stdout, proc.stderr


def _without(doc, keys=("seconds", "compile_seconds", "provenance")):
    """The document less its wall-time fields and the provenance record of the command that printed
    it (the only ones a run on other processes may change)."""
    if isinstance(doc, dict):
        return {k: _without(v, keys) for k, v in doc.items() if k not in keys}
    if isinstance(doc, list):
        return [_without(v, keys) for v in doc]
    return doc


# ----------------------------------------------------------------------------- no cluster needed


def test_light_commands_never_import_dask():
    code = ("import atexit, sys; "
            "atexit.register(lambda: sys.stderr.write('DASK:' + ','.join("
            "m for m in ('dask', 'distributed') if m in sys.modules))); "
            "sys.argv = ['rkhp'] + sys.argv[1:]; "
            "from rkhp_cli.main import main; main()")
    for args in (["conditions", "--order", "5", "--degenerate"],
                 ["search", "--stages", "2", "--order", "2", "--restarts", "2", "--workers", "2"]):
        env = {k: v for k, v in os.environ.items() if k != "DASK_SCHEDULER_ADDRESS"}
        proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env)
        assert proc.returncode == 0, proc.stderr
        assert proc.stderr.split("DASK:")[1].strip() == "", args


def test_scheduler_choice():
    assert scheduler_address(1, None, {}) is None
    assert scheduler_address(1, " tcp://10.0.0.1:8786 ", {}) == "tcp://10.0.0.1:8786"
    env = {"DASK_SCHEDULER_ADDRESS": "tcp://127.0.0.1:8786"}
    assert scheduler_address(1, None, env) == "tcp://127.0.0.1:8786"
    assert scheduler_address(4, None, env) is None  # --workers N asks for this machine
    for workers, scheduler in [(2, "tcp://127.0.0.1:8786"), (0, None), (1, "tcp://x:1; rm -rf /"), (1, "")]:
        with pytest.raises(InputError):
            scheduler_address(workers, scheduler, {})


def test_unreachable_scheduler_is_one_line_exit_2():
    rc, _, err = _rkhp("search", "--stages", "2", "--order", "2", env={"DASK_SCHEDULER_ADDRESS": "tcp://127.0.0.1:1"})
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "cannot reach the Dask scheduler" in err
    assert "connection refused" in err  # nothing listens on port 1: told at once, not after Dask's retries


def test_unknown_scheduler_host_is_one_line_at_once():
    host = "no-such-host.invalid"  # RFC 2606: a name that never resolves
    try:
        socket.getaddrinfo(host, 8786)
    except socket.gaierror as exc:
        if exc.errno != socket.EAI_NONAME:
            pytest.skip(f"this machine's resolver answers {exc} (not 'no such name')")
    else:
        pytest.skip(f"this machine's resolver gives {host} an address")
    rc, _, err = _rkhp("search", "--stages", "2", "--order", "2", "--scheduler", f"tcp://{host}:8786")
    # told by the probe before Dask's client, not "within 10 s" after its retries
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "unknown host" in err, err


# ----------------------------------------------------------------------------- on a cluster of two workers


@pytest.fixture(scope="module")
def cluster():
    with loopback_cluster(2) as running:
        yield running


def test_search_on_the_cluster_equals_the_single_process_run(cluster):
    from rkhp.search.driver import SearchOptions, search

    options = SearchOptions(seed=1, restarts=12)
    alone = json_form(search(3, 4, "degenerate", options=options))
    with open_executor(scheduler=cluster.address) as dask:
        on_cluster = json_form(search(3, 4, "degenerate", options=options, executor=dask))
    # the command line, with the scheduler from the environment (Dask's convention)
    rc, by_env, err = _rkhp("search", "--stages", "3", "--order", "4", "--degenerate", "--seed", "1",
                            "--restarts", "12", "--format", "json", env={"DASK_SCHEDULER_ADDRESS": cluster.address})
    assert rc == 0, err
    assert alone["found"] and alone["verified_orders"]["degenerate"]["order"] == 4
    assert _without(on_cluster) == _without(alone) == _without(json.loads(by_env))


def test_converge_on_the_cluster_equals_the_single_process_run(cluster):
    from rkhp.integrators.methods import resolve_methods
    from rkhp.studies.converge import converge
    from rkhp.systems import get_system

    alone = converge(get_system("rigid-body"), resolve_methods(["paper-three-stage"]), [20], refinements=3)
    rc, on_cluster, err = _rkhp("converge", "rigid-body", "--method", "paper-three-stage", "--steps", "20",
                                "--refinements", "3", "--format", "json", "--scheduler", cluster.address)
    assert rc == 0, err
    alone = json.loads(json.dumps(json_form(alone)))  # as the command writes it
    assert [m["expected_order"] for m in alone["methods"]] == [4]
    assert _without(json.loads(on_cluster)) == _without(alone)


def test_ensemble_on_the_cluster_equals_the_single_process_run(cluster):
    from rkhp.integrators import integrate_ensemble
    from rkhp.studies.bench import ensemble_starts
    from rkhp.systems import get_system

    system = get_system("rigid-body")
    starts = ensemble_starts(system, 9, seed=4)
    alone = integrate_ensemble(system, "paper-three-stage", 0.05, 40, starts)
    with open_executor(scheduler=cluster.address) as dask:
        spread = integrate_ensemble(system, "paper-three-stage", 0.05, 40, starts, executor=dask)
    assert np.array_equal(alone, spread)
    # each final state is the one trajectory's (not a reordering of the chunks)
    from rkhp.integrators import integrate_rkhp

    assert np.array_equal(spread[5], integrate_rkhp(system, "paper-three-stage", 0.05, 40, x0=starts[5]).final_state)


def test_stress_bench_and_relations_on_the_cluster_equal_the_single_process_runs(cluster):
    from rkhp.integrators.methods import resolve_methods
    from rkhp.series.relation_derivation import derive_relations
    from rkhp.studies.bench import bench
    from rkhp.studies.stress import stress
    from rkhp.systems import get_system
    from rkhp.trees.relations import shipped_relations

    system = get_system("lotka-volterra")
    methods = resolve_methods(["paper-three-stage"])

    def studies(executor=None):
        s = stress(system, methods, long_steps=600, sweep_coarsest=8, round_off_steps=(30, 100, 300),
                   executor=executor)
        b = bench(system, methods, peers=("scipy:dop853",), steps=(20, 40), tolerances=(1e-6, 1e-8), repeats=1,
                  executor=executor)
        return _without(json_form(s)), _without(json_form(b), ("seconds", "cpu_seconds", "compile_seconds", "cheapest"))

    alone = studies()
    with open_executor(scheduler=cluster.address) as dask:
        assert studies(dask) == alone
        relations = derive_relations(5, seed=0, executor=dask)
    assert alone[0]["long_run"]["runs"][0]["casimir_max"] < 1e-12  # the RKHP method keeps the Casimir
    assert relations.orders == shipped_relations().orders[:5]  # the shipped data (orders <= 8)


def test_ctrl_c_cancels_the_tasks_on_the_cluster(cluster):
    import time

    from rkhp.search.multistart import Problem, run_restarts

    def interrupt_after_two(done, total):
        if done == 2:
            raise KeyboardInterrupt

    def attempts_on_the_scheduler(dask_scheduler):
        return [key for key in dask_scheduler.tasks if str(key).startswith("attempt")]

    with open_executor(scheduler=cluster.address) as dask:
        run = run_restarts(Problem(4, 5, "degenerate"), 40, seed=2, executor=dask, stop_after=None,
                           on_progress=interrupt_after_two)
        left = dask._client.run_on_scheduler(attempts_on_the_scheduler)
        for _ in range(50):
            if not left:
                break
            time.sleep(0.2)
            left = dask._client.run_on_scheduler(attempts_on_the_scheduler)
    assert run.interrupted and len(run.attempts) == 2  # the two finished before Ctrl-C
    assert left == []


def test_killing_a_worker_mid_search_changes_nothing(cluster):
    # last in this file: it leaves the cluster with one worker
    from rkhp.search.multistart import Problem, run_restarts

    problem = Problem(4, 5, "degenerate")
    alone = run_restarts(problem, 10, seed=2, stop_after=None)
    killed = []

    def kill_after_two(done, total):
        if done == 2 and not killed:
            cluster.workers[0].kill()
            killed.append(done)

    with open_executor(scheduler=cluster.address) as dask:
        again = run_restarts(problem, 10, seed=2, executor=dask, stop_after=None, on_progress=kill_after_two)
    assert killed and cluster.workers[0].wait(timeout=30) != 0
    assert [a.index for a in again.attempts] == list(range(10))
    assert [(a.x, a.residual, a.success) for a in again.attempts] == [(a.x, a.residual, a.success)
                                                                      for a in alone.attempts]
    assert any(a.success for a in alone.attempts)
