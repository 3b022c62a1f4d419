"""The dependencies: the ranges of pyproject.toml, the pins of constraints.txt, and the form of
numba's inliner that rkhp.taylor.compiler patches (docs/development.md)."""

from __future__ import annotations

import re
import sys
import tomllib
import types
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parent.parent
TESTED_EXTRAS = ("test", "distributed")  # what `make install` installs


def requirements() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    listed = project["dependencies"] + [r for extra in TESTED_EXTRAS for r in project["optional-dependencies"][extra]]
    return [Requirement(r) for r in listed]


def pins() -> dict[str, str]:
    out = {}
    for line in (ROOT / "constraints.txt").read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, _, version = line.partition("==")
            assert version, f"constraints.txt: {line!r} is not NAME==VERSION"
            out[canonical(name)] = version
    return out


def canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def test_every_dependency_is_pinned_within_its_range():
    pinned = pins()
    for req in requirements():
        assert canonical(req.name) in pinned, f"{req.name} has no pin in constraints.txt"
        assert req.specifier.contains(pinned[canonical(req.name)], prereleases=True), \
            f"constraints.txt pins {req.name}=={pinned[canonical(req.name)]}, outside pyproject's {req}"


@pytest.mark.parametrize("name", ["numba", "numpy", "click"])
def test_the_engines_dependencies_are_bounded_above(name):
    req = next(r for r in requirements() if canonical(r.name) == name)
    assert any(s.operator == "<" for s in req.specifier), f"{req} has no upper bound"


def test_installed_numba_is_within_its_range():
    req = next(r for r in requirements() if r.name == "numba")
    assert req.specifier.contains(metadata.version("numba")), \
        f"numba {metadata.version('numba')} installed, pyproject.toml asks {req}"


def test_numba_inliner_has_the_form_the_patch_expects():
    """Fails loudly when a numba release changes the inliner that rkhp.taylor.compiler patches:
    the patch is then skipped (correct, slower compiles) and must be reviewed before numba's upper
    bound moves."""
    from numba.core import inline_closurecall

    from rkhp.taylor.compiler import inlining_precondition

    missing = inlining_precondition()
    assert not missing, (f"numba {metadata.version('numba')}'s inliner changed; rkhp.taylor.compiler's "
                         f"cheap inlining is not applied: {'; '.join(missing)}")
    worker = inline_closurecall.InlineWorker
    assert worker.rkhp_cheap_inlining
    assert worker.inline_ir.__name__ == "inline_ir_cheaply"
    assert worker.inline_function.__name__ == "inline_function_fresh"


def test_precondition_sees_a_changed_inliner():
    """The check fails on an inliner of another form: deepcopy elsewhere, inline_function doing more."""
    import copy

    from rkhp.taylor.compiler import inlining_precondition

    source = '''
import copy
class InlineWorker:
    def inline_ir(self, ir):
        return copy.deepcopy(ir), copy.deepcopy(ir)
    def inline_function(self, function):
        ir = self.run_untyped_passes(function)
        ir = self.validate(ir)
        return self.inline_ir(ir, function.__code__.co_freevars)
'''
    module = types.ModuleType("fake_numba_inliner")
    sys.modules[module.__name__] = module
    try:
        exec(compile(source, module.__name__, "exec"), module.__dict__)
        missing = inlining_precondition(module)
    finally:
        del sys.modules[module.__name__]
    assert any("deepcopy is called in ['InlineWorker.inline_ir']" in m for m in missing), missing
    assert any("inline_function does not use exactly" in m for m in missing), missing
    module.copy = types.SimpleNamespace(deepcopy=copy.deepcopy)
    assert inlining_precondition(module)[0] == "fake_numba_inliner.copy is not the copy module"


def test_inlined_function_gives_the_same_values():
    """A function inlined at two sites (`inline="always"`) under the patched inliner: same values
    as the plain Python function."""
    from rkhp.taylor.compiler import numba

    def poly(x, k):
        y = 0.0
        for i in range(k):
            y = y * x + (i + 1)
        return y

    inlined = numba.njit(inline="always")(poly)

    @numba.njit
    def twice(x):
        return inlined(x, 4) - 2.0 * inlined(-x, 3)

    for x in (0.0, 0.5, -1.25, 3.0):
        assert twice(x) == poly(x, 4) - 2.0 * poly(-x, 3)


def test_numba_cache_save_has_the_form_the_lock_expects():
    """Fails loudly when a numba release changes the cache save that rkhp.taylor.compiler locks:
    the lock is then not applied and `rkhp compile` runs in one process."""
    from numba.core import caching

    from rkhp.taylor.compiler import _save_locked, cache_save_precondition, parallel_compiles_safe

    missing = cache_save_precondition()
    assert not missing, (f"numba {metadata.version('numba')}'s cache save changed; rkhp.taylor.compiler's "
                         f"lock is not applied: {'; '.join(missing)}")
    assert caching.IndexDataCacheFile.save is _save_locked
    assert parallel_compiles_safe()


def test_cache_save_precondition_sees_a_changed_save():
    from rkhp.taylor.compiler import cache_save_precondition

    class IndexDataCacheFile:
        def save(self, key, data):
            self._save_data(self._data_name(1), data)  # no index: another form

    module = types.SimpleNamespace(__name__="fake_numba_caching", IndexDataCacheFile=IndexDataCacheFile)
    missing = cache_save_precondition(module)
    assert any("save does not use exactly" in m for m in missing), missing
    assert any("has no _load_index" in m for m in missing), missing
    assert cache_save_precondition(types.SimpleNamespace(__name__="empty")) == ["empty has no IndexDataCacheFile"]


def test_numba_cache_has_the_form_the_healing_expects():
    """Fails loudly when a numba release changes the cache loads and saves that
    rkhp.taylor.kernel_cache replaces: a damaged cache file would then be a traceback again."""
    from numba.core import caching

    import rkhp.taylor.compiler  # noqa: F401 - applies the healing
    from rkhp.taylor.kernel_cache import heal_precondition

    missing = heal_precondition(caching)
    assert not missing, (f"numba {metadata.version('numba')}'s cache changed; damaged cache files are not "
                         f"healed: {'; '.join(missing)}")
    assert caching.Cache.rkhp_robust


def test_heal_precondition_sees_a_changed_cache_module():
    from rkhp.taylor.kernel_cache import heal_precondition

    class Cache:
        def _load_overload(self, sig, target_context):
            return self._cache_file.load((sig, target_context))  # no rebuild: another form

        def save_overload(self, sig, data):  # numba's own form
            with self._guard_against_spurious_io_errors():
                self._save_overload(sig, data)

    module = types.SimpleNamespace(__name__="fake_numba_caching", Cache=Cache, IndexDataCacheFile=object)
    missing = heal_precondition(module)
    assert any("Cache._load_overload does not use exactly" in m for m in missing), missing
    assert "IndexDataCacheFile has no _load_index" in missing
    assert not any("save_overload" in m for m in missing)
    assert heal_precondition(types.SimpleNamespace(__name__="empty")) == ["empty has no Cache or no "
                                                                           "IndexDataCacheFile"]


def _save_entries(folder: str, first: int, count: int) -> None:
    """Save ``count`` entries, keys first..first+count-1, each with its own key as data, into the
    index of one function in ``folder`` (a process of the race test below)."""
    from numba.core.caching import IndexDataCacheFile

    import rkhp.taylor.compiler  # noqa: F401 - the locked save

    cache_file = IndexDataCacheFile(folder, "kernel", ("stamp", 1))
    for key in range(first, first + count):
        cache_file.save(("signature", key), {"key": key, "payload": "x" * 20_000})


def test_processes_saving_into_one_index_lose_nothing(tmp_path):
    """Four processes save 40 versions each of one function at once: every version is in the index
    and its data file holds that version (numba's unlocked save loses entries and can point one
    version at another's data)."""
    import multiprocessing

    from numba.core.caching import IndexDataCacheFile

    context = multiprocessing.get_context("spawn")
    workers = [context.Process(target=_save_entries, args=(str(tmp_path), 1000 * k, 40)) for k in range(4)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(120)
        assert worker.exitcode == 0
    cache_file = IndexDataCacheFile(str(tmp_path), "kernel", ("stamp", 1))
    keys = [("signature", 1000 * k + i) for k in range(4) for i in range(40)]
    assert sorted(cache_file._load_index()) == sorted(keys)
    for key in keys:
        assert cache_file.load(key)["key"] == key[1]
    assert not list(tmp_path.glob("*.tmp.*"))


def test_numba_cache_locator_has_the_form_rkhp_refines():
    """Fails loudly when a numba release changes how its cache finds a function's folder or checks
    its source: rkhp's locator is then not used, and each checkout compiles for itself."""
    from numba.core import caching

    from rkhp.taylor.compiler import SourcesLocator, locator_precondition

    missing = locator_precondition()
    assert not missing, (f"numba {metadata.version('numba')}'s cache locators changed; rkhp's SourcesLocator "
                         f"is not used: {'; '.join(missing)}")
    assert caching.CacheImpl._locator_classes[0] is SourcesLocator


def test_locator_precondition_sees_a_changed_cache_module():
    from numba.core import caching

    from rkhp.taylor.compiler import locator_precondition

    class TimeStamped(caching.UserProvidedCacheLocator):
        def get_source_stamp(self):
            return Path(self._py_file).stat().st_mtime  # numba's older stamp: differs between copies

    stamped = types.SimpleNamespace(CacheImpl=types.SimpleNamespace(_locator_classes=[TimeStamped]),
                                    UserProvidedCacheLocator=TimeStamped)
    assert locator_precondition(stamped) == ["UserProvidedCacheLocator.get_source_stamp does not hash the "
                                             "source file's content"]
    renamed = types.SimpleNamespace(CacheImpl=types.SimpleNamespace(_locator_classes=(TimeStamped,)))
    assert locator_precondition(renamed) == ["CacheImpl._locator_classes is not a list holding "
                                             "UserProvidedCacheLocator"]


SHARED_COMPILE = """
import json, sys
import rkhp
from rkhp.taylor.linalg import lu_factor
import numpy as np
from rkhp.taylor.compiler import is_cached
before = is_cached(lu_factor)
A = np.array([[0.0, 2.0], [3.0, 1.0]])
assert lu_factor(A, np.zeros(2, np.int64))
print(json.dumps({"package": rkhp.__file__, "cached_before": before,
                  "hits": sum(lu_factor.stats.cache_hits.values()),
                  "misses": sum(lu_factor.stats.cache_misses.values())}))
"""


def _run_in_copy(copy: Path, environ: dict) -> dict:
    import json
    import subprocess

    out = subprocess.run([sys.executable, "-c", SHARED_COMPILE], capture_output=True, text=True, timeout=300,
                         env=dict(environ, PYTHONPATH=str(copy)), cwd=copy)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["package"] == str(copy / "rkhp" / "__init__.py")
    return report


def test_two_copies_of_the_sources_share_one_compile(tmp_path):
    """A kernel compiled by one checkout of rkhp is loaded, not compiled, by another checkout of the
    same sources elsewhere on disk (rkhp's cache folder); in a user's NUMBA_CACHE_DIR, numba's own
    locator keeps one folder per path, and the second copy compiles again."""
    import os
    import shutil

    copies = [tmp_path / name for name in ("first", "second")]
    for copy in copies:
        shutil.copytree(ROOT / "rkhp", copy / "rkhp", ignore=shutil.ignore_patterns("__pycache__"))
    environ = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    shared = dict(environ, XDG_CACHE_HOME=str(tmp_path / "home-cache"))
    first, second = (_run_in_copy(copy, shared) for copy in copies)
    assert (first["cached_before"], first["misses"]) == (False, 1)
    assert (second["cached_before"], second["hits"], second["misses"]) == (True, 1, 0)

    users = dict(environ, NUMBA_CACHE_DIR=str(tmp_path / "users-cache"))
    first, second = (_run_in_copy(copy, users) for copy in copies)
    assert (first["misses"], second["cached_before"], second["misses"]) == (1, False, 1)
