"""The dependencies: the ranges of pyproject.toml, the pins of constraints.txt, and the form of
each piece of numba that rkhp.taylor.numba_patches replaces (docs/development.md)."""

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


def _patched_numba():
    """numba as rkhp's compiled modules take it: every patch applied (`rkhp.taylor.compiler`)."""
    from rkhp.taylor.compiler import numba

    return numba


#: what each patch of rkhp.taylor.numba_patches replaces or calls of numba, and the first 16 hex
#: digits of the sha256 of its source in numba 0.68.1, the pin of constraints.txt, read from
#: numba's files: a numba whose source of one of them differs fails here, and that patch must be
#: read against the new source (then its digests written here) before the pin moves
NUMBA_FORMS = {
    "cheap_inlining": {
        "numba.core.inline_closurecall:InlineWorker.inline_ir": "cb5d4f1d4f7ffab0",
        "numba.core.inline_closurecall:InlineWorker.inline_function": "4bb626a769afcf0c",
    },
    "locked_saves": {
        "numba.core.caching:IndexDataCacheFile.save": "926b10d2188c9c41",
        "numba.core.caching:IndexDataCacheFile._save_index": "3bf8060007868d82",
        "numba.core.caching:IndexDataCacheFile._save_data": "b8c875732364b2ac",
        "numba.core.caching:IndexDataCacheFile._data_name": "851ff952f5913a5f",
    },
    "robust_cache": {
        "numba.core.caching:IndexDataCacheFile._load_index": "27048a88ba1d8308",
        "numba.core.caching:Cache._load_overload": "fa926a535976c5c8",
        "numba.core.caching:Cache.save_overload": "bc8571ddb40a85f7",
        "numba.core.compiler:CompileResult._reduce": "9afa7275887ba500",
    },
    "sources_locator": {
        "numba.core.caching:UserProvidedCacheLocator": "a429549705e39f67",
        "numba.core.caching:_SourceFileBackedLocatorMixin": "5751bf9e11237ffd",
        "numba.core.caching:CacheImpl.__init__": "df6754da619b0899",
    },
}


def numba_form(name: str) -> str:
    """The first 16 hex digits of the sha256 of the source of ``module:Class.function`` as the
    installed numba's file holds it (read with ast, nothing of it imported but its path)."""
    import ast
    import hashlib
    from importlib.util import find_spec

    module, _, qualname = name.partition(":")
    text = Path(find_spec(module).origin).read_text(encoding="utf-8")
    node = ast.parse(text)
    for part in qualname.split("."):
        node = next(n for n in node.body if isinstance(n, ast.ClassDef | ast.FunctionDef) and n.name == part)
    return hashlib.sha256(ast.get_source_segment(text, node).encode()).hexdigest()[:16]


def test_every_patch_has_the_forms_it_was_checked_on():
    from rkhp.taylor.numba_patches import PATCHES

    assert sorted(NUMBA_FORMS) == sorted(PATCHES)


@pytest.mark.parametrize("patch", sorted(NUMBA_FORMS))
def test_the_pinned_numba_has_the_form_each_patch_was_checked_on(patch):
    """Each patch against the numba of constraints.txt: the source of every piece of numba it
    replaces or calls is the one it was written for (`NUMBA_FORMS`), and it is applied."""
    from rkhp.taylor import numba_patches

    installed, pinned = metadata.version("numba"), pins()["numba"]
    if installed != pinned:
        pytest.skip(f"numba {installed} installed; the forms are those of the pin {pinned}")
    forms = {name: numba_form(name) for name in NUMBA_FORMS[patch]}
    changed = sorted(name for name, digest in forms.items() if digest != NUMBA_FORMS[patch][name])
    assert not changed, f"numba {installed} changed what rkhp.taylor.numba_patches.{patch} relies on: {changed}"
    _patched_numba()
    assert patch in numba_patches.apply(None, ()).applied


LAZY_PATCHES = r"""
import json, sys
from pathlib import Path

import rkhp
import rkhp.integrators.methods
import rkhp.taylor.compiler as compiler

loaded = "numba" in sys.modules
from numba.core import caching, inline_closurecall

def state():
    return {"inliner": getattr(inline_closurecall.InlineWorker, "rkhp_cheap_inlining", False),
            "save": caching.IndexDataCacheFile.save.__module__,
            "load": caching.Cache._load_overload.__module__,
            "locators": [c.__name__ for c in caching.CacheImpl._locator_classes],
            "cache_dir": caching.config.CACHE_DIR}

before = state()
from rkhp.taylor.compiler import numba
from rkhp.taylor import numba_patches
from rkhp.taylor.linalg import lu_factor

first = numba_patches._APPLIED[0]
again = numba_patches.apply("elsewhere", ())
other = Path(sys.argv[1])
other.write_text("import numba\n\n\n@numba.njit(cache=True)\ndef twice(x):\n    return x + x\n")
sys.path.insert(0, str(other.parent))
import other_kernels

print(json.dumps({"loaded": loaded, "before": before, "after": state(), "same": again is first,
                  "folder": compiler.RKHP_CACHE_DIR, "rkhp": lu_factor._cache.cache_path,
                  "other": other_kernels.twice._cache.cache_path}))
"""


def test_numba_is_patched_once_at_the_first_compiled_module_and_its_cache_folder_left(tmp_path):
    """Importing rkhp, its integrators' names and rkhp.taylor.compiler imports no numba and patches
    nothing; the first compiled module applies every patch once (a second `apply` changes
    nothing), and numba's own cache folder setting stays unset: rkhp's kernels go to rkhp's
    folder, a function of another file to numba's own place (beside its source)."""
    import json
    import os
    import subprocess

    environ = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    environ["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    out = subprocess.run([sys.executable, "-c", LAZY_PATCHES, str(tmp_path / "other_kernels.py")],
                         capture_output=True, text=True, timeout=300, env=environ)
    assert out.returncode == 0, out.stderr[-3000:]
    report = json.loads(out.stdout)
    assert report["loaded"] is False
    assert report["before"] == {"inliner": False, "save": "numba.core.caching", "load": "numba.core.caching",
                                "locators": report["before"]["locators"], "cache_dir": ""}
    assert "SourcesLocator" not in report["before"]["locators"]
    after = report["after"]
    assert after["inliner"] is True and after["cache_dir"] == ""
    assert after["save"] == after["load"] == "rkhp.taylor.numba_patches"
    assert after["locators"].count("SourcesLocator") == 1 and after["locators"][0] == "SourcesLocator"
    assert report["same"] is True
    assert report["folder"].startswith(str(tmp_path / "xdg" / "rkhp" / "numba"))
    assert report["rkhp"] == str(Path(report["folder"]) / "taylor")
    assert report["other"] == str(tmp_path / "__pycache__")


def test_numba_inliner_has_the_form_the_patch_expects():
    """Fails loudly when a numba release changes the inliner that rkhp.taylor.numba_patches
    patches: the patch is then skipped (correct, slower compiles) and must be reviewed before
    numba's upper bound moves."""
    from numba.core import inline_closurecall

    from rkhp.taylor.numba_patches import inlining_precondition

    _patched_numba()
    missing = inlining_precondition()
    assert not missing, (f"numba {metadata.version('numba')}'s inliner changed; rkhp.taylor.numba_patches' "
                         f"cheap inlining is not applied: {'; '.join(missing)}")
    worker = inline_closurecall.InlineWorker
    assert worker.rkhp_cheap_inlining
    assert worker.inline_ir.__name__ == "inline_ir_cheaply"
    assert worker.inline_function.__name__ == "inline_function_fresh"


def test_precondition_sees_a_changed_inliner():
    """The check fails on an inliner of another form: deepcopy elsewhere, inline_function doing more."""
    import copy

    from rkhp.taylor.numba_patches import inlining_precondition

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
    numba = _patched_numba()

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
    """Fails loudly when a numba release changes the cache save that rkhp.taylor.numba_patches
    locks: the lock is then not applied and `rkhp compile` runs in one process."""
    from numba.core import caching

    from rkhp.taylor.numba_patches import _save_locked, cache_save_precondition, parallel_compiles_safe

    _patched_numba()
    missing = cache_save_precondition()
    assert not missing, (f"numba {metadata.version('numba')}'s cache save changed; rkhp.taylor.numba_patches' "
                         f"lock is not applied: {'; '.join(missing)}")
    assert caching.IndexDataCacheFile.save is _save_locked
    assert parallel_compiles_safe()


def test_cache_save_precondition_sees_a_changed_save():
    from rkhp.taylor.numba_patches import cache_save_precondition

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
    rkhp.taylor.numba_patches replaces: a damaged cache file would then be a traceback again."""
    from numba.core import caching

    from rkhp.taylor.numba_patches import heal_precondition

    _patched_numba()
    missing = heal_precondition(caching)
    assert not missing, (f"numba {metadata.version('numba')}'s cache changed; damaged cache files are not "
                         f"healed: {'; '.join(missing)}")
    assert caching.Cache.rkhp_robust


def test_heal_precondition_sees_a_changed_cache_module():
    from rkhp.taylor.numba_patches import heal_precondition

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

    from rkhp.taylor.compiler import numba  # noqa: F401 - numba with rkhp's patches: the locked save

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

    from rkhp.taylor.numba_patches import SourcesLocator, locator_precondition

    _patched_numba()
    missing = locator_precondition()
    assert not missing, (f"numba {metadata.version('numba')}'s cache locators changed; rkhp's SourcesLocator "
                         f"is not used: {'; '.join(missing)}")
    assert caching.CacheImpl._locator_classes[0] is SourcesLocator


def test_locator_precondition_sees_a_changed_cache_module():
    from numba.core import caching

    from rkhp.taylor.numba_patches import locator_precondition

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
