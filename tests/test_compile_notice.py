"""The first run on a machine says that it compiles: one line on stderr when stderr is a
terminal, nothing in JSON mode or through a pipe (the rules of the progress bars).

numba keeps compiled kernels in its disk cache; an empty NUMBA_CACHE_DIR is a machine that has
never run rkhp, and numba writing index files there after a run is numba's own record of a compile.
"""

from __future__ import annotations

import json
import os
import pty
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rkhp.integrators.kernels import COMPOSITE_SECONDS, KERNELS, TAPE, cold_start
from rkhp.integrators.methods import resolve_method, resolve_system

NOTICE = b"compiling the integrator kernels once for this machine, ~"


def _fresh_cache(tmp_path) -> dict:
    """The environment of a machine whose numba cache is empty."""
    return dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))


def _stderr_on_a_terminal(args, env, until: bytes | None = None, timeout: float = 60, stdout=None) -> bytes:
    """Run `args` with stderr on a pseudo-terminal; return what it wrote there. With `until`, stop
    the process (its whole session) as soon as that text has appeared."""
    master, slave = pty.openpty()
    proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=stdout or subprocess.DEVNULL, stderr=slave,
                            env=env, start_new_session=True)
    os.close(slave)
    seen, deadline = b"", time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.2)
            if ready:
                try:
                    chunk = os.read(master, 4096)
                except OSError:  # the terminal closed: the process ended
                    break
                if not chunk:
                    break
                seen += chunk
                if until is not None and until in seen:
                    break
            elif proc.poll() is not None:
                break
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        os.close(master)
    return seen


def _notice_script(enabled: bool) -> list[str]:
    return [sys.executable, "-c", f"from rkhp_cli.options import compile_notice; compile_notice(('rkhp',), {enabled})"]


def test_a_run_leaves_its_kernels_in_the_cache():
    resolve_method("rk4").integrate(resolve_system("rigid-body"), 0.1, 1)  # compiles, or loads the cache
    assert not cold_start(["rkhp"])


def test_the_cache_is_asked_for_the_class_of_the_system_tapes(tmp_path):
    """A kernel compiled for the rigid body's tapes (no composite operation) is not compiled for
    a class of tapes that holds composite ones: those runs are announced, with the composite
    kernels' compile time added (rkhp.integrators.kernels.COMPOSITE_SECONDS). In a cache of its
    own (the shared one may hold any class that another test compiled): the interpreter compiled
    for the rigid body's class by one evaluation of grad H."""
    script = ("import json; from rkhp.integrators.kernels import cold_start; "
              "from rkhp.integrators.methods import resolve_system; from rkhp.taylor.ops import PHIMV, SPRAY; "
              "from rkhp.taylor.tape import Tape, tape_class; s = resolve_system('rigid-body'); "
              "s.grad_hamiltonian(s.x0); both = cold_start(['rkhp'], tape_class((PHIMV, SPRAY))); "
              "print(json.dumps([cold_start(['rkhp'], Tape).kernels, both.kernels, both.seconds]))")
    proc = subprocess.run([sys.executable, "-c", script], env=_fresh_cache(tmp_path), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    plain, both, seconds = json.loads(proc.stdout)
    assert plain == ["rkhp.integrators.driver.drive"]
    assert both == ["rkhp.taylor.interpreter.run_tape", "rkhp.integrators.driver.drive"]
    expected = TAPE.seconds + KERNELS["rkhp"][0].seconds + COMPOSITE_SECONDS["spray"] + COMPOSITE_SECONDS["phimv"]
    assert seconds == pytest.approx(expected)


def test_an_empty_cache_lacks_the_kernels_of_each_kind(tmp_path):
    script = ("import json; from rkhp.integrators.kernels import cold_start; "
              "print(json.dumps({k: cold_start([k]) for k in ('rkhp', 'classical', 'taylor')}))")
    proc = subprocess.run([sys.executable, "-c", script], env=_fresh_cache(tmp_path), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    cold = json.loads(proc.stdout)
    tape = "rkhp.taylor.interpreter.run_tape"
    assert cold["rkhp"][0] == [tape, "rkhp.integrators.driver.drive"]
    assert cold["classical"][0] == [tape, "rkhp.integrators.classical._rk_loop"]
    assert cold["taylor"][0] == [tape, "rkhp.integrators.driver.drive"]  # THP's substeps on the driver
    assert not list(tmp_path.rglob("*.nbi"))  # nothing compiled


def test_the_notice_follows_the_progress_rules(tmp_path):
    env = _fresh_cache(tmp_path)
    shown = _stderr_on_a_terminal(_notice_script(True), env)
    assert NOTICE in shown and b" s" in shown.split(NOTICE)[1] and shown.count(b"\n") == 1
    assert _stderr_on_a_terminal(_notice_script(False), env) == b""  # JSON mode
    piped = subprocess.run(_notice_script(True), env=env, capture_output=True, timeout=120)
    assert piped.returncode == 0 and piped.stderr == b""  # stderr not a terminal


@pytest.mark.parametrize("args, seconds", [
    (["integrate", "rigid-body", "--method", "rk4", "--steps", "100"], 8),  # run_tape 2.9 + drive 5.5
    (["converge", "rigid-body", "--method", "classical:rk4"], 4),  # run_tape 2.9 + _rk_loop 1.3 + H loop 0.3
    (["check", "rigid-body"], 3),  # run_tape 2.9
    (["check", "nambu"], 20),  # run_tape 2.9 + the spray kernel 17.4
])
def test_commands_say_so_before_compiling(tmp_path, args, seconds):
    shown = _stderr_on_a_terminal([sys.executable, "-m", "rkhp", *args], _fresh_cache(tmp_path), until=b" s\r\n")
    assert NOTICE + f"{seconds} s".encode() in shown


@pytest.mark.slow
def test_a_cold_json_run_is_quiet_and_then_warm(tmp_path):
    env = _fresh_cache(tmp_path)
    out = tmp_path / "out.json"
    args = [sys.executable, "-m", "rkhp", "integrate", "rigid-body", "--method", "rk4", "--steps", "100",
            "--format", "json"]
    with open(out, "wb") as stdout:
        shown = _stderr_on_a_terminal(args, env, timeout=600, stdout=stdout)
    assert shown == b""
    doc = json.loads(out.read_text())
    assert doc["status"] == "ok" and doc["compile_seconds"] > 2  # it did compile
    assert any((tmp_path / "numba-cache").rglob("driver.drive-*.nbi"))
    # the same machine again: in the cache, so no notice even on a terminal
    assert NOTICE not in _stderr_on_a_terminal(args[:-2], env, timeout=600)


def test_compiling_ahead_leaves_no_run_of_a_builtin_system_cold():
    """`rkhp compile` (rkhp.integrators.ahead): after it, no kind of run on any built-in system
    lacks a kernel, and a run on a terminal says nothing about compiling."""
    from rkhp.integrators.ahead import compile_ahead, tape_classes
    from rkhp.systems import builtin_systems, get_system

    classes = tape_classes()
    assert sorted(cls.__name__ for cls in classes) == ["Tape", "Tape_phimv", "Tape_spray"]
    assert sorted(n for names in classes.values() for n in names) == sorted(builtin_systems())
    run = compile_ahead(jobs=2)
    assert [item.tape_class for item in run.classes] == [cls.__name__ for cls in classes]
    assert 1 <= run.jobs <= 2
    for name in builtin_systems():
        assert not cold_start(tuple(KERNELS), type(get_system(name).h_tape)), name
    args = [sys.executable, "-m", "rkhp", "integrate", "charged-particle", "--method", "rk4", "--steps", "10"]
    assert NOTICE not in _stderr_on_a_terminal(args, dict(os.environ))


@pytest.mark.slow
def test_rkhp_compile_on_an_empty_cache_compiles_every_class(tmp_path):
    env = _fresh_cache(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "rkhp", "compile", "--format", "json"], env=env,
                          capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["cache_dir"] == str(tmp_path / "numba-cache")
    for item in report["classes"]:
        assert "rkhp.taylor.interpreter.run_tape" in item["compiled"], item
        assert "rkhp.integrators.driver.drive" in item["compiled"], item
    args = [sys.executable, "-m", "rkhp", "integrate", "nambu", "--method", "gauss2", "--steps", "10"]
    assert NOTICE not in _stderr_on_a_terminal(args, env, timeout=600)


# ----------------------------------------------------------------------------- other versions' folders


def _folder(path, files: dict[str, int]) -> int:
    """A folder holding files of the given sizes; their total size."""
    for name, size in files.items():
        (path / name).parent.mkdir(parents=True, exist_ok=True)
        (path / name).write_bytes(b"x" * size)
    return sum(files.values())


def test_prune_removes_the_folders_of_other_versions_only(tmp_path):
    from rkhp.taylor.compiler import cache_dir, prune_other_versions

    root = tmp_path / "rkhp" / "numba"
    current = root / cache_dir().name
    kept = _folder(current, {"taylor/interpreter.run_tape-1.py311.nbi": 10})
    old = _folder(root / "0123456789abcdef", {"taylor/a.nbi": 100, "integrators/b.nbc": 2000})
    older = _folder(root / "fedcba9876543210", {"c.nbc": 7})
    _folder(root / "notes", {"readme": 3})  # not a name rkhp gives
    _folder(root / "0123456789ABCDEF", {"d": 4})  # upper case: not a name rkhp gives
    (root / "00000000000000aa").write_bytes(b"a file, not a folder")
    outside = tmp_path / "elsewhere"
    _folder(outside, {"e": 5})
    (root / "00000000000000bb").symlink_to(outside, target_is_directory=True)

    pruned = prune_other_versions(current)

    assert pruned.folders == (str(root / "0123456789abcdef"), str(root / "fedcba9876543210"))
    assert pruned.bytes == old + older == 2107
    assert sorted(p.name for p in root.iterdir()) == ["00000000000000aa", "00000000000000bb", "0123456789ABCDEF",
                                                      cache_dir().name, "notes"]
    assert (outside / "e").read_bytes() == b"xxxxx"
    assert (current / "taylor/interpreter.run_tape-1.py311.nbi").stat().st_size == kept
    assert prune_other_versions(current) == (tuple(), 0)
    assert prune_other_versions(tmp_path / "nothing" / cache_dir().name) == (tuple(), 0)


def _compile_command(monkeypatch, rkhp_cache_dir, *args):
    """`rkhp compile ARGS` in this process, rkhp's cache folder set to ``rkhp_cache_dir`` and the
    compile itself left out (tested above with the real cache)."""
    from cli_run import in_process

    from rkhp.integrators import ahead
    from rkhp.taylor import compiler

    monkeypatch.setattr(compiler, "RKHP_CACHE_DIR", rkhp_cache_dir)
    monkeypatch.setattr(ahead, "compile_ahead", lambda jobs=None, on_part=None: ahead.AheadRun((), 1, 0.0))
    return in_process(["compile", *args], None)


def test_rkhp_compile_prune_reports_what_it_removed(tmp_path, monkeypatch):
    from rkhp.taylor.compiler import cache_dir

    root = tmp_path / "rkhp" / "numba"
    current = root / cache_dir().name
    _folder(current, {"kept": 1})
    _folder(root / "0123456789abcdef", {"a": 1500, "b": 500})
    ran = _compile_command(monkeypatch, str(current), "--prune", "--format", "json")
    assert ran.returncode == 0, ran.output
    report = json.loads(ran.stdout)
    assert report["pruned"] == {"folders": [str(root / "0123456789abcdef")], "bytes": 2000}
    assert sorted(p.name for p in root.iterdir()) == [current.name]
    ran = _compile_command(monkeypatch, str(current), "--prune")
    assert ran.returncode == 0 and ran.stdout.rstrip().endswith("No cache folders of other versions to remove.")
    ran = _compile_command(monkeypatch, str(current), "--format", "json")
    assert json.loads(ran.stdout)["pruned"] is None


def test_rkhp_compile_prune_leaves_a_user_cache_folder_alone(tmp_path, monkeypatch):
    (tmp_path / "0123456789abcdef").mkdir()
    ran = _compile_command(monkeypatch, None, "--prune")
    assert ran.returncode == 2
    assert len(ran.stderr.strip().splitlines()) == 1 and "NUMBA_CACHE_DIR" in ran.stderr
    assert (tmp_path / "0123456789abcdef").is_dir()


def test_a_folder_that_cannot_be_removed_is_one_line(tmp_path, monkeypatch):
    import shutil

    from rkhp.taylor import compiler

    root = tmp_path / "rkhp" / "numba"
    current = root / compiler.cache_dir().name
    _folder(root / "0123456789abcdef", {"a": 1})
    _folder(root / "fedcba9876543210", {"b": 1})

    remove = shutil.rmtree

    def refuse(path, *args, **kwargs):
        if Path(path).name == "fedcba9876543210":
            raise PermissionError(13, "Permission denied")
        remove(path)

    monkeypatch.setattr(compiler.shutil, "rmtree", refuse)
    line = f"cannot remove the cache folder {root / 'fedcba9876543210'} (Permission denied); 1 of 2 removed before it"
    with pytest.raises(OSError) as caught:
        compiler.prune_other_versions(current)
    assert caught.value.strerror == line
    assert sorted(p.name for p in root.iterdir()) == ["fedcba9876543210"]
    _folder(root / "0123456789abcdef", {"a": 1})
    ran = _compile_command(monkeypatch, str(current), "--prune")
    assert ran.returncode == 2 and ran.stderr.strip().splitlines() == [f"rkhp: error: {line}"], ran.stderr
