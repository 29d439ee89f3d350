"""Reading and validating a YAML input file: one context shared by model, subject and
study files, so every message has the same form ``<file>: <entry path>: <what is
expected>`` and the same checks apply everywhere.

Reading (:func:`read_yaml`, :func:`parse_yaml`):

- the safe loader only, so nothing in a file is evaluated (libyaml's C parser when PyYAML
  has it: about 10× faster on a mandible model file);
- a key given twice in one mapping, anywhere in the file, is an error naming the entry
  and both line numbers (PyYAML would silently keep the last one);
- ``1e10`` and ``1.0e10`` are numbers (YAML 1.1 reads them as strings);
- malformed YAML, undecodable text and nesting too deep are one-line errors with the
  line and column;
- a file above :data:`openfdk.io.limits.INPUT_FILE_BYTES` is refused before it is read,
  and a document with too many aliases, a recursive alias or too many nodes once its
  aliases are expanded before any value is built (:mod:`.yamlgraph`).

Validating (:class:`YamlContext`): typed getters (mapping with allowed and required
keys and a suggestion for a misspelt key, number with its unit and bounds, integer,
boolean, string, choice, vector) that raise the file kind's own error class (a
``ValueError`` subclass) naming the file and the entry path.
"""

from __future__ import annotations

import difflib
import re
from pathlib import Path

import numpy as np
import yaml

from . import limits
from .yamlgraph import check_graph, may_pass_limits, scan_events

#: largest plausible coordinate (m): :data:`openfdk.io.limits.MAX_COORDINATE`
MAX_LENGTH = limits.MAX_COORDINATE
_BASE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _Loader(_BASE_LOADER):
    """The safe loader, with YAML 1.2 floats (``1e10``, ``-2.5E-3``)."""


_FLOAT_12 = re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+$")
_Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789."))


def _key_text(node) -> str:
    return str(node.value) if isinstance(node, yaml.ScalarNode) else f"<{node.tag.rsplit(':', 1)[-1]}>"


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def duplicate_keys(node, path="") -> list:
    """Every key given twice in one mapping of a composed YAML node tree, as
    ``(entry path, first line, second line)`` (lines 1-based), in file order."""
    found, seen_nodes, stack = [], set(), [(node, path)]
    while stack:
        n, p = stack.pop()
        if id(n) in seen_nodes:  # aliases share nodes: visit each once
            continue
        seen_nodes.add(id(n))
        if isinstance(n, yaml.MappingNode):
            first = {}
            for k, v in n.value:
                if k.tag == "tag:yaml.org,2002:merge":
                    continue
                key = _key_text(k)
                if isinstance(k, yaml.ScalarNode) and key in first:
                    found.append((_join(p, key), first[key] + 1, k.start_mark.line + 1))
                else:
                    first.setdefault(key, k.start_mark.line)
                stack.append((v, _join(p, key)))
        elif isinstance(n, yaml.SequenceNode):
            stack.extend((v, f"{p}[{i}]") for i, v in enumerate(n.value))
    return sorted(found, key=lambda f: f[2])


def parse_yaml(text: str, source: str, error=ValueError):
    """The parsed content of YAML ``text``; ``source`` names it in messages. Raises
    ``error`` (an exception class) with a one-line message. The document's nodes and
    aliases are counted from the parser's events before it is composed
    (:func:`.yamlgraph.scan_events`), its expanded size checked before it is built
    (:func:`.yamlgraph.check_graph`)."""
    limits.check_count(len(text), "INPUT_FILE_BYTES", source, "", "characters", error)
    loader = _Loader(text)
    try:
        if may_pass_limits(text):  # a short text cannot: no second parse for it
            scan_events(_Loader(text), source, error)
        node = loader.get_single_node()
        if node is None:
            return None
        check_graph(node, source, error)
        dups = duplicate_keys(node)
        if dups:
            where, a, b = dups[0]
            more = f" ({len(dups) - 1} more duplicate keys)" if len(dups) > 1 else ""
            raise error(f"{source}: {where}: duplicate key, given at lines {a} and {b}; "
                        f"each key may appear once{more}")
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"{source}: malformed YAML{where}: {problem}") from None
    except RecursionError:
        raise error(f"{source}: malformed YAML: nested too deeply") from None
    finally:
        loader.dispose()


def read_yaml(path, error=ValueError, what="file", source=None):
    """The parsed content of the YAML file ``path``. Raises ``error`` (an exception
    class) with a one-line message when the file is missing ("<what> '<path>' does not
    exist"), unreadable, not UTF-8 text, malformed ("<name>: malformed YAML at line L,
    column C: <problem>") or has a duplicate key ("<name>: <entry>: duplicate key, given
    at lines A and B"), or is above a size limit (:mod:`openfdk.io.limits`; the file size is
    checked before reading). ``source`` (default: the file name) names the file in messages."""
    path = Path(path)
    source = path.name if source is None else source
    if not path.is_file():
        raise error(f"{what} {str(path)!r} does not exist")
    limits.check_file_bytes(path, "INPUT_FILE_BYTES", source, error)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{source}: not a YAML text file (byte {exc.start} is not UTF-8)") from None
    except OSError as exc:
        raise error(f"{source}: cannot be read: {exc.strerror or exc}") from None
    from .placeholders import placeholder

    if (why := placeholder(text[:200].encode())) is not None:
        raise error(f"{source}: {why}")
    return parse_yaml(text, source, error)


def did_you_mean(name, known) -> str:
    """``; did you mean '<closest>'?`` when one of the names ``known`` is close to
    ``name`` (difflib's ratio >= 0.6), else ``""``: the hint of a misspelt name."""
    hint = difflib.get_close_matches(str(name), [str(a) for a in known], n=1)
    return f"; did you mean {hint[0]!r}?" if hint else ""


def unknown_key(key, allowed) -> str:
    """``unknown key; did you mean '<closest>'?`` (or ``; allowed: [...]`` when no
    allowed key is close): the message for a key not in ``allowed``."""
    return "unknown key" + (did_you_mean(key, allowed) or f"; allowed: {sorted(map(str, allowed))}")


def _unit(unit):
    return f" ({unit})" if unit else ""


class YamlContext:
    """Where we are in a file (for messages) and its unit scales.

    source : the file as named in messages; error_type : the exception class raised (a
    ValueError subclass of the file kind); length, angle : scale of the file's declared
    length and angle units to m and rad; base_dir : folder that relative paths in the
    file are relative to.
    """

    error_type = ValueError

    def __init__(self, source, length=1.0, angle=1.0, base_dir=None, error_type=None):
        self.source = str(source)
        self.length = length
        self.angle = angle
        self.base_dir = Path(base_dir) if base_dir else Path(".")
        if error_type is not None:
            self.error_type = error_type

    def error(self, path, msg):
        """The file kind's error: ``<source>: <path>: <msg>``."""
        return self.error_type(f"{self.source}: {path}: {msg}" if path else f"{self.source}: {msg}")

    # -- typed getters ----------------------------------------------------------------
    def mapping(self, value, path, allowed=None, required=()):
        """``value`` as a mapping; with ``allowed``, an unknown key is an error with the
        closest allowed key as a suggestion; a missing ``required`` key is an error."""
        if not isinstance(value, dict):
            raise self.error(path or "(top level)", f"expected a mapping of keys, got {_kind(value)}")
        if allowed is not None:
            allowed = list(allowed)
            for k in value:
                if k not in allowed:
                    raise self.error(_join(path, str(k)), unknown_key(k, allowed))
        for k in required:
            if k not in value:
                raise self.error(path or "(top level)", f"missing required key {k!r}")
        return value

    def keys(self, value, path, allowed, required=()):
        """Same as :meth:`mapping` with ``allowed`` keys."""
        return self.mapping(value, path, allowed, required)

    def number(self, value, path, unit="", positive=False, nonnegative=False, low=None, high=None):
        """A finite number (int or float, not a boolean) -> float, within the bounds.
        Text like ``1.0e5`` (what YAML 1.1 readers make of 1.2 floats, e.g. in a mapping
        parsed elsewhere) counts as that number."""
        if isinstance(value, str) and _FLOAT_12.match(value.strip()):
            value = float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(path, f"expected a number{_unit(unit)}, got {value!r}")
        try:
            v = float(value)
        except OverflowError:
            v = float("inf")
        if not np.isfinite(v):
            raise self.error(path, f"expected a finite number{_unit(unit)}, got {value!r}")
        if positive and v <= 0:
            raise self.error(path, f"must be > 0{_unit(unit)}, got {v:g}")
        if nonnegative and v < 0:
            raise self.error(path, f"must be >= 0{_unit(unit)}, got {v:g}")
        if (low is not None and v < low) or (high is not None and v > high):
            raise self.error(path, f"must be in [{low}, {high}]{_unit(unit)}, got {v:g}")
        return v

    def integer(self, value, path, low=None, high=None):
        """An integer (not a boolean) within [low, high]."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(path, f"expected an integer, got {value!r}")
        if (low is not None and value < low) or (high is not None and value > high):
            bounds = f">= {low}" if high is None else f"in [{low}, {high}]"
            raise self.error(path, f"must be an integer {bounds}, got {value}")
        return int(value)

    def boolean(self, value, path):
        if not isinstance(value, bool):
            raise self.error(path, f"expected true or false, got {value!r}")
        return value

    def string(self, value, path):
        if not isinstance(value, str) or not value:
            raise self.error(path, f"expected a non-empty name, got {value!r}")
        return value

    def choice(self, value, path, options, what="value"):
        if not isinstance(value, str) or value not in options:
            raise self.error(path, f"unknown {what} {value!r}; expected one of {list(options)}")
        return value

    def vector(self, value, path, n=None, shape=None, unit=""):
        """A list (of lists) of finite numbers -> float array of ``shape`` or ``(n,)``."""
        if not _numeric_tree(value):
            raise self.error(path, f"expected {f'{n} numbers' if n else 'a list of numbers'}{_unit(unit)}, got {value!r}")
        try:
            arr = np.array(value, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise self.error(path, f"expected a list of numbers{_unit(unit)}, got {value!r}") from None
        if shape is not None and arr.shape != shape:
            raise self.error(path, f"expected shape {shape}, got {arr.shape}")
        if n is not None and arr.shape != (n,):
            raise self.error(path, f"expected {n} numbers{_unit(unit)}, got {value!r}")
        if not np.all(np.isfinite(arr)):
            raise self.error(path, f"expected finite numbers{_unit(unit)}, got {value!r}")
        return arr

    def position(self, value, path):
        """A length triple in the file unit -> (3,) m, each at most
        :data:`openfdk.io.limits.MAX_COORDINATE` m."""
        p = self.vector(value, path, n=3) * self.length
        if np.max(np.abs(p)) > limits.MAX_COORDINATE:
            raise self.error(path, f"coordinates beyond {limits.MAX_COORDINATE:g} m are not plausible, got {value!r}")
        return p


def _numeric_tree(value, depth=0) -> bool:
    """Whether ``value`` is a number or a (nested, at most 3 deep) list of numbers."""
    if isinstance(value, bool):
        return False
    if isinstance(value, (int, float)):
        return True
    if isinstance(value, (list, tuple)) and depth < 3:
        return all(_numeric_tree(v, depth + 1) for v in value)
    return False


def _kind(value):
    return {dict: "a mapping", list: "a list", str: "text", type(None): "nothing"}.get(type(value), type(value).__name__)
