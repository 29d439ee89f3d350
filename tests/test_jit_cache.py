"""numba's cache stamped by every numba-using source of a package (openfdk.numerics.jit_cache).

The oracle is independent of the stamp: a throw-away package whose cached ``a.f`` returns
``b.g() + 1``; after ``b.py`` is edited to return 10, a fresh process must print 11. A
control package that does not register keeps running its cached ``f`` (numba stamps only
``a.py``) and prints the stale 2, which shows the check can fail. With nothing changed, the
second process loads ``f`` from the cache.
"""

import json
import os
import subprocess
import sys
import types

import pytest

import openfdk
from openfdk.numerics import jit_cache

A = """
from numba import njit

from .b import g


@njit(cache=True)
def f():
    return g() + 1
"""
B = """
from numba import njit


@njit(cache=True)
def g():
    return {value}
"""
REGISTERS = """
import os

from openfdk.numerics import jit_cache

jit_cache.install(os.path.dirname(__file__))
"""
RUN = """
import json, sys
if sys.argv[1] == "numba first":  # registration at once, not through the import hook
    import numba
import pkg.a, ctl.a

out = {}
for name, mod in (("pkg", pkg.a), ("ctl", ctl.a)):
    value = mod.f()
    stats = mod.f.stats
    out[name] = value
    out[name + " hits"] = sum(stats.cache_hits.values())
    out[name + " misses"] = sum(stats.cache_misses.values())
    out[name + " locator"] = type(mod.f._cache._impl.locator).__name__
print(json.dumps(out))
"""


def _write_packages(root, value):
    for name, init in (("pkg", REGISTERS), ("ctl", "")):
        (root / name).mkdir(exist_ok=True)
        (root / name / "__init__.py").write_text(init)
        (root / name / "a.py").write_text(A)
        (root / name / "b.py").write_text(B.format(value=value))


def _run(root, how, cache_dir):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(root)
    env["PYTHONDONTWRITEBYTECODE"] = "1"  # b.py is rewritten within the second
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = str(cache_dir)
    proc = subprocess.run([sys.executable, "-c", RUN, how], cwd=root, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("how, where", [("import hook", "__pycache__"),
                                        ("numba first", "NUMBA_CACHE_DIR")])
def test_editing_a_callee_recompiles_the_caller_and_an_unchanged_tree_loads_the_cache(
        tmp_path, how, where):
    root = tmp_path / "src"
    root.mkdir()
    cache_dir = tmp_path / "numba-cache" if where == "NUMBA_CACHE_DIR" else None
    _write_packages(root, 1)

    first = _run(root, how, cache_dir)
    assert (first["pkg"], first["ctl"]) == (2, 2)
    assert (first["pkg hits"], first["pkg misses"]) == (0, 1)  # compiled and saved
    kind = "InTreeCacheLocator" if cache_dir is None else "UserProvidedCacheLocator"
    assert first["pkg locator"] == "Package" + kind
    assert first["ctl locator"] == kind  # numba's own, for a package that did not register
    index_dir = root / "pkg" / "__pycache__" if cache_dir is None else cache_dir
    assert any(p.name.startswith("a.f-") for p in index_dir.rglob("*.nbi"))

    again = _run(root, how, cache_dir)  # nothing changed: the stamp does not break caching
    assert (again["pkg"], again["pkg hits"], again["pkg misses"]) == (2, 1, 0)
    assert (again["ctl"], again["ctl hits"], again["ctl misses"]) == (2, 1, 0)

    _write_packages(root, 10)  # only b.py changes (and its size: 1 -> 10)
    edited = _run(root, how, cache_dir)
    assert (edited["pkg"], edited["pkg hits"], edited["pkg misses"]) == (11, 0, 1)
    # the control: numba stamps a.py only, so f's cached machine code with the old g runs
    assert (edited["ctl"], edited["ctl hits"]) == (2, 1), (
        "numba no longer serves the stale f of a package that did not register: it tracks "
        "callees itself now, and this test no longer shows that the stamp is needed")


def test_import_openfdk_does_not_import_numba():
    code = "import sys, openfdk; print('numba' in sys.modules, 'numpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.split() == ["False", "False"]


def test_openfdk_kernels_carry_the_package_stamp():
    from openfdk.recruitment import polynomial

    package_dir = openfdk.__path__[0]
    kernel = polynomial._solve_polynomial_kernel
    assert isinstance(kernel._cache._impl.locator, jit_cache.locator_classes(package_dir))
    own, package = kernel._cache._cache_file._source_stamp
    assert package == jit_cache.package_stamp(jit_cache._normal(package_dir))


def test_the_stamp_hashes_numba_sources_by_content_and_path_only(tmp_path):
    stamp = jit_cache.package_stamp.__wrapped__  # not the once-per-process value
    (tmp_path / "sub").mkdir()
    (tmp_path / "k.py").write_text("import numba\nX = 1\n")
    (tmp_path / "sub" / "m.py").write_text("from numba import njit\n")
    (tmp_path / "plain.py").write_text("X = 1\n")
    before = stamp(str(tmp_path))
    assert len(before) == 64 and stamp(str(tmp_path)) == before
    (tmp_path / "plain.py").write_text("X = 2\n")  # no numba in it: not hashed
    (tmp_path / "__pycache__").mkdir()
    (tmp_path / "__pycache__" / "k.py").write_text("import numba\n")  # skipped
    (tmp_path / "notes.txt").write_text("numba")  # not a .py file
    assert stamp(str(tmp_path)) == before
    (tmp_path / "k.py").write_text("import numba\nX = 2\n")  # same size, new content
    changed = stamp(str(tmp_path))
    assert changed != before
    (tmp_path / "sub" / "m.py").rename(tmp_path / "sub" / "n.py")  # path is hashed too
    assert stamp(str(tmp_path)) not in (before, changed)


def test_locators_accept_only_files_inside_the_package(tmp_path):
    def func():
        pass

    inside, outside = tmp_path / "pkg" / "m.py", tmp_path / "other" / "m.py"
    for path in (inside, outside):
        path.parent.mkdir()
        path.write_text("")
    classes = jit_cache.locator_classes(str(tmp_path / "pkg"))
    assert jit_cache.locator_classes(str(tmp_path / "pkg" / ".")) == classes  # one set per dir
    in_tree = classes[1]
    assert in_tree.from_function(func, str(outside)) is None
    locator = in_tree.from_function(func, str(inside))
    assert isinstance(locator, in_tree)
    assert locator.get_cache_path() == str(inside.parent / "__pycache__")
    own, package = locator.get_source_stamp()
    assert package == jit_cache.package_stamp(jit_cache._normal(str(tmp_path / "pkg")))


def test_register_is_idempotent_and_falls_back_when_numba_differs(tmp_path, monkeypatch):
    import numba.core
    import numba.core.caching as caching

    listed = caching.CacheImpl._locator_classes
    monkeypatch.setattr(caching.CacheImpl, "_locator_classes", list(listed))
    assert jit_cache.register(str(tmp_path)) and jit_cache.register(str(tmp_path))
    ours = jit_cache.locator_classes(str(tmp_path))
    assert caching.CacheImpl._locator_classes[:3] == list(ours)
    assert caching.CacheImpl._locator_classes[3:] == listed

    for fake in (types.ModuleType("numba.core.caching"),  # no CacheImpl
                 types.SimpleNamespace(CacheImpl=types.SimpleNamespace(_locator_classes=[]))):
        monkeypatch.setattr(numba.core, "caching", fake)
        monkeypatch.setitem(sys.modules, "numba.core.caching", fake)
        assert jit_cache.register(str(tmp_path / "elsewhere")) is False
