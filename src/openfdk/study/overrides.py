"""Parameter overrides: edits of a parsed model file addressed by dotted path.

A model file is plain data (a YAML mapping), so a study parameter is an edit of that
mapping before the model is built. The syntax (docs/studies.md):

* ``section.name.key`` walks mappings by key, e.g. ``ligaments.tmj_ligament_r1.stiffness``
  or ``contacts.tmj_r.pressure_modulus``; a list is indexed by a whole number
  (``bodies.mandible.position.2``).
* A segment may be a shell-style glob (``*``, ``?``, ``[abc]``, :mod:`fnmatch`):
  ``ligaments.*.stiffness``, ``ligaments.tmj_ligament_r*.reference_strain``; on a list,
  ``*`` matches every item.
* Every intermediate segment must match at least one existing entry. The last segment,
  when it is a plain name (no glob), may add that key to each matched mapping, so a
  default can be overridden (``reference_strain`` of a ligament that does not write
  one); the model loader then checks the key is valid. A glob last segment must match
  an existing key.
* An override that matches nothing is an :class:`OverrideError` naming the path, the
  segment that matched nothing and the keys that were there.
* ``mode: set`` replaces the value; ``mode: multiply`` multiplies an existing number
  (e.g. all muscle strengths × 1.2).

Values are exactly what the model file would hold, in the file's declared units
(``units.length`` for lengths; forces and stiffnesses are SI whatever the file says).
"""

from __future__ import annotations

import copy
import difflib
import fnmatch
from dataclasses import dataclass

GLOB_CHARACTERS = frozenset("*?[")
MODES = ("set", "multiply")


class OverrideError(ValueError):
    """An override path that matches nothing, or a value that cannot be applied."""


@dataclass(frozen=True)
class Override:
    """One edit: ``path`` (dotted, globs allowed), ``value`` (any YAML value, file
    units), ``mode`` ("set" or "multiply")."""

    path: str
    value: object
    mode: str = "set"

    def __post_init__(self):
        if self.mode not in MODES:
            raise OverrideError(f"override {self.path!r}: mode must be one of {MODES}, got {self.mode!r}")
        if not isinstance(self.path, str) or not self.path or any(s == "" for s in self.path.split(".")):
            raise OverrideError(f"override path {self.path!r}: expected dotted names like 'ligaments.*.stiffness'")


def _is_glob(segment: str) -> bool:
    return any(c in GLOB_CHARACTERS for c in segment)


def _children(node, segment):
    """Keys (mapping) or indices (list) of ``node`` matched by ``segment``."""
    if isinstance(node, dict):
        if _is_glob(segment):
            return [k for k in node if fnmatch.fnmatchcase(str(k), segment)]
        return [k for k in node if str(k) == segment]
    if isinstance(node, list):
        if segment == "*":
            return list(range(len(node)))
        if segment.lstrip("-").isdigit() and -len(node) <= int(segment) < len(node):
            return [int(segment) % len(node)]
    return []


def _nothing_matched(path, segment, prefix, parents, source):
    where = ".".join(prefix) or "(top level)"
    keys = sorted({str(k) for p in parents if isinstance(p, dict) for k in p})
    lists = [len(p) for p in parents if isinstance(p, list)]
    hint = ""
    close = difflib.get_close_matches(segment, keys, n=1)
    if close:
        hint = f"; did you mean {close[0]!r}?"
    if keys:
        shown = keys if len(keys) <= 12 else keys[:12] + ["..."]
        there = f"keys there: {shown}"
    elif lists:
        there = f"a list of {lists[0]} items there (use an index or '*')"
    else:
        there = "a plain value there, not a mapping or list"
    return OverrideError(
        f"{source}: override {path!r} matches nothing: no entry matches {segment!r} under {where!r} ({there}){hint}"
    )


def resolve(data, path: str, source="model", allow_new_key=True):
    """Concrete locations of a dotted ``path`` in ``data``: a list of key tuples
    (mapping keys / list indices). Raises OverrideError naming the path when it matches
    nothing (see the module docstring for the rules)."""
    segments = path.split(".")
    frontier = [((), data)]
    for depth, segment in enumerate(segments):
        last = depth == len(segments) - 1
        nxt = []
        for keys, node in frontier:
            children = _children(node, segment)
            nxt += [(keys + (child,), node[child]) for child in children]
            if not children and last and allow_new_key and not _is_glob(segment) and isinstance(node, dict):
                nxt.append((keys + (segment,), None))  # a new key in an existing mapping
        if not nxt:
            raise _nothing_matched(path, segment, segments[:depth], [n for _, n in frontier], source)
        frontier = nxt
    return [keys for keys, _ in frontier]


def _multiply(old, factor, where, path):
    def number(x, what):
        if isinstance(x, bool):
            raise OverrideError(f"override {path!r} (multiply) at {where}: {what} {x!r} is not a number")
        if isinstance(x, str):
            try:
                return float(x)  # YAML 1.1 reads 1.0e10 as a string
            except ValueError:
                raise OverrideError(f"override {path!r} (multiply) at {where}: {what} {x!r} is not a number") from None
        if isinstance(x, (int, float)):
            return float(x)
        if isinstance(x, list):
            return [number(v, what) for v in x]
        raise OverrideError(f"override {path!r} (multiply) at {where}: {what} {x!r} is not a number")

    f = number(factor, "factor")
    if isinstance(f, list):
        raise OverrideError(f"override {path!r} (multiply): the factor must be one number, got {factor!r}")
    if old is None:
        raise OverrideError(f"override {path!r} (multiply) at {where}: there is no existing value to multiply")
    o = number(old, "the existing value")
    return [v * f for v in o] if isinstance(o, list) else o * f


def apply_overrides(data, overrides, source="model"):
    """A deep copy of the model mapping ``data`` with ``overrides`` (a sequence of
    :class:`Override`, applied in order: later ones win) applied. ``data`` is not
    modified. Raises OverrideError naming the first path that matches nothing."""
    out = copy.deepcopy(data)
    for ov in overrides:
        for keys in resolve(out, ov.path, source, allow_new_key=(ov.mode == "set")):
            parent = out
            for k in keys[:-1]:
                parent = parent[k]
            where = ".".join(str(k) for k in keys)
            if ov.mode == "multiply":
                parent[keys[-1]] = _multiply(parent[keys[-1]], ov.value, where, ov.path)
            else:
                parent[keys[-1]] = copy.deepcopy(ov.value)
    return out
