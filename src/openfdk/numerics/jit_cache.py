"""numba's on-disk cache stamped by every numba-using source of a package, not one file.

What: numba stores each ``@njit(cache=True)`` function's machine code with a *source
stamp* of the one file that defines the function, and reuses it while that stamp matches.
This module adds a second part to the stamp of every function defined under a package
directory: :func:`package_stamp`, a SHA-256 over the sorted (path relative to the
package, content) of the package's ``.py`` files whose text contains ``numba``.

Why: a cached function has its callees (njit functions of other modules) and the global
constants it reads compiled into it. When only the callee's module changes, numba's own
stamp of the caller's file is unchanged and the stale machine code keeps running (an edit
of ``recruitment/reduction.py`` was not seen by ``_solve_polynomial_kernel`` of
``recruitment/polynomial.py``). An njit function can call only njit code, so its callees
and their modules' constants are in files that mention numba; with all of them in every
stamp, editing one recompiles the package's kernels on their next call. A fresh install
has no cache; an editable install updated with ``git pull`` is the case this fixes.
Not covered: a constant imported into a numba module from a module that never mentions
numba, and data files read at import.

How: subclasses of numba's three source-file locators (``UserProvidedCacheLocator`` for
``NUMBA_CACHE_DIR``, ``InTreeCacheLocator`` for ``__pycache__``, ``UserWideCacheLocator``;
``_``-prefixed before numba 0.60), each accepting only files under the package directory
and returning ``(numba's stamp, package stamp)``, put at the front of
``CacheImpl._locator_classes`` in numba's order. numba picks a function's locator when the
decorator enables caching, so the registration must come first: :func:`install` registers
at once when numba is loaded, else right after ``numba.core.caching`` is imported (so
``import openfdk`` does not import numba). When numba's internals differ, nothing is
registered and numba's default stamps apply.

Cost: the package stamp is computed once per process (``functools.lru_cache``), at the
first cached function's decoration. For openfdk (260 ``.py`` files, 2.4 MB, read; the 60
that mention numba hashed) it took 4–9 ms with the files in the page cache and 35 ms with
them evicted (``posix_fadvise(DONTNEED)``), measured on the development machine. The
price of the wider stamp: editing any numba-using file recompiles all the package's
kernels on their next call (1–2 min for a whole run), not only that file's.
"""

from __future__ import annotations

import functools
import hashlib
import os
import sys

#: numba's source-file locators, in the order of its ``_locator_classes``; the second
#: name of each is its spelling before numba 0.60
_LOCATORS = (("UserProvidedCacheLocator", "_UserProvidedCacheLocator"),
             ("InTreeCacheLocator", "_InTreeCacheLocator"),
             ("UserWideCacheLocator", "_UserWideCacheLocator"))
_CACHING = "numba.core.caching"


def _normal(path):
    return os.path.normcase(os.path.realpath(path))


@functools.lru_cache(maxsize=None)
def package_stamp(package_dir):
    """Hex SHA-256 over the ``.py`` files under ``package_dir`` (``__pycache__`` skipped)
    whose bytes contain ``numba``: for each, in sorted order of its ``/``-separated path
    relative to ``package_dir``, that path, a NUL byte and the SHA-256 of its content.
    Unreadable files are left out. Computed once per process and directory."""
    entries = []
    for folder, subfolders, files in os.walk(package_dir):
        subfolders[:] = [d for d in subfolders if d != "__pycache__"]
        for name in files:
            if not name.endswith(".py"):
                continue
            path = os.path.join(folder, name)
            try:
                with open(path, "rb") as f:
                    data = f.read()
            except OSError:
                continue
            if b"numba" in data:
                rel = os.path.relpath(path, package_dir).replace(os.sep, "/")
                entries.append((rel, hashlib.sha256(data).digest()))
    digest = hashlib.sha256()
    for rel, content_hash in sorted(entries):
        digest.update(rel.encode("utf-8") + b"\0" + content_hash)
    return digest.hexdigest()


def _inside(py_file, package_dir):
    try:
        return os.path.commonpath([_normal(py_file), package_dir]) == package_dir
    except ValueError:  # another drive, or relative against absolute
        return False


@functools.lru_cache(maxsize=None)
def _locator_classes(package_dir, caching):
    """numba's three source-file locators of module ``caching``, each subclassed to
    accept only files under ``package_dir`` (normalised) and to add the package stamp."""
    classes = []
    for names in _LOCATORS:
        base = next(getattr(caching, n) for n in names if hasattr(caching, n))

        def from_function(cls, py_func, py_file, _base=base):
            if not _inside(py_file, cls._package_dir):
                return None
            return _base.from_function.__func__(cls, py_func, py_file)

        def get_source_stamp(self, _base=base):
            return _base.get_source_stamp(self), package_stamp(self._package_dir)

        classes.append(type(f"Package{names[0]}", (base,), {
            "__doc__": f"numba's {names[0]} for files under {package_dir}; stamp "
                       "(numba's stamp of the file, package_stamp of the directory).",
            "__module__": __name__, "_package_dir": package_dir,
            "from_function": classmethod(from_function),
            "get_source_stamp": get_source_stamp}))
    return tuple(classes)


def locator_classes(package_dir):
    """The three locator classes for ``package_dir`` (imports numba); the same objects on
    every call for the same directory."""
    import numba.core.caching

    return _locator_classes(_normal(package_dir), numba.core.caching)


def register(package_dir):
    """Put the locators of ``package_dir`` at the front of numba's locator list, once.
    Returns True when they are in it; False when numba is missing or its caching internals
    are not as expected (numba's default stamps then apply). Never raises."""
    try:
        import numba.core.caching as caching

        impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl")
        listed = impl._locator_classes
        ours = _locator_classes(_normal(package_dir), caching)
        if ours[0] not in listed:
            listed[0:0] = ours
        return True
    except Exception:  # ImportError, AttributeError, StopIteration, TypeError: numba differs
        return False


class _RegisterAfterImport:
    """A ``sys.meta_path`` finder that hands out numba's own spec of
    ``numba.core.caching`` with a loader that, after running the module, calls
    :func:`register` for its package directories and removes this finder."""

    def __init__(self):
        self.package_dirs = []

    def find_spec(self, fullname, path, target=None):
        if fullname != _CACHING:
            return None
        spec = None
        for finder in sys.meta_path:
            if finder is not self and hasattr(finder, "find_spec"):
                spec = finder.find_spec(fullname, path, target)
                if spec is not None:
                    break
        if spec is None or not hasattr(spec.loader, "exec_module"):
            return spec
        spec.loader = _RegisteringLoader(spec.loader, self)
        return spec

    def registered(self):
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        for package_dir in self.package_dirs:
            register(package_dir)


class _RegisteringLoader:
    """numba's loader of ``numba.core.caching``; registers once the module has run."""

    def __init__(self, loader, finder):
        self._loader, self._finder = loader, finder

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        self._loader.exec_module(module)
        self._finder.registered()

    def __getattr__(self, name):
        return getattr(self._loader, name)


def install(package_dir):
    """:func:`register` ``package_dir`` now if ``numba.core.caching`` is loaded, else as
    soon as it is imported (before any function can be decorated). Does not import numba;
    never raises. Call it from the package's ``__init__`` before importing any module that
    decorates with ``cache=True``."""
    try:
        if _CACHING in sys.modules:
            register(package_dir)
            return
        hook = next((f for f in sys.meta_path if isinstance(f, _RegisterAfterImport)), None)
        if hook is None:
            hook = _RegisterAfterImport()
            sys.meta_path.insert(0, hook)
        if _normal(package_dir) not in map(_normal, hook.package_dirs):
            hook.package_dirs.append(package_dir)
    except Exception:  # an unusual import system: numba's default stamps apply
        pass
