"""The file format of checkpoint parts: named numpy arrays plus a JSON structure, in one
``.npz`` read with ``numpy.load(allow_pickle=False)`` — loading it cannot run code.

:func:`encode` turns a payload (plain values, containers, numpy arrays and scalars and
the few openfdk classes a checkpoint holds) into bytes; :func:`decode` turns them back.
Each object is a JSON node with a type tag; arrays (and numpy scalars, as 0-d arrays)
are stored in the ``.npz`` under names ``a0``, ``a1``, … that the nodes refer to. The
structure itself is the array ``structure`` (UTF-8 JSON bytes).

Nodes: JSON ``null``/``true``/``false``/numbers/strings are themselves; every other
value is an object ``{"t": tag, …}``:

- ``list`` / ``tuple`` ``{"t", "v": [nodes]}``; ``dict`` ``{"t", "v": [[key, value], …]}``
  (keys are nodes, so int keys and order are kept);
- ``nd`` ``{"t", "a": name, "ro": bool}`` a numpy array (the same array object twice is
  stored once and restored as one object, as pickle does); ``np`` ``{"t", "a": name}``
  a numpy scalar;
- ``enum`` ``{"t", "c": class, "v": value}``; ``obj`` ``{"t", "c": class, "f": {field:
  node}}`` an instance of one of :func:`known_classes` (dataclasses and ``BodyStates``),
  rebuilt field by field without calling its constructor.

Only these tags and classes are accepted; anything else is a :class:`FormatError`.
"""

from __future__ import annotations

import dataclasses
import enum
import io
import json

import numpy as np

STRUCTURE = "structure"
FORMAT = "openfdk-checkpoint-1"


class FormatError(ValueError):
    """Bytes that are not a checkpoint part of this format (or an unknown type in it)."""


_CLASSES = None


def known_classes():
    """{name: class} of the openfdk classes a checkpoint may hold."""
    global _CLASSES
    if _CLASSES is None:
        from ..dynamics.results import InverseDynamicsResult
        from ..fdk.analysis import FDKResult
        from ..fdk.contact_step import ContactSplit
        from ..fdk.settings import FDKSettings
        from ..kinematics.analysis import KinematicsResult
        from ..kinematics.determinate import FrameSolve
        from ..model.framedata import FrameData
        from ..model.state import BodyStates
        from ..recruitment.result import RecruitmentResult
        from ..study.chunks import Segment, SegmentResult
        from .status import FrameReport, FrameStatus, Reason

        classes = (FrameStatus, Reason, FrameReport, FrameSolve, FrameData, RecruitmentResult, BodyStates,
                   KinematicsResult, InverseDynamicsResult, FDKResult, FDKSettings, ContactSplit, Segment, SegmentResult)
        _CLASSES = {c.__name__: c for c in classes}
    return _CLASSES


def _attributes(cls):
    """The attribute names stored for an instance of a known class."""
    if dataclasses.is_dataclass(cls):
        return tuple(f.name for f in dataclasses.fields(cls))
    return tuple(cls.__slots__)


class _Encoder:
    def __init__(self):
        self.arrays = {}
        self._by_id = {}
        self._keep = []  # the encoded arrays, so that their ids stay unique while encoding

    def array(self, a):
        name = self._by_id.get(id(a))
        if name is None:
            if a.dtype.hasobject:
                raise TypeError("checkpoint: numpy arrays of Python objects cannot be saved")
            name = f"a{len(self.arrays)}"
            self.arrays[name] = a
            self._by_id[id(a)] = name
            self._keep.append(a)
        return name

    def node(self, v):
        if v is None or type(v) in (bool, str, int, float):
            return v
        if isinstance(v, np.ndarray):
            return {"t": "nd", "a": self.array(v), "ro": not v.flags.writeable}
        if isinstance(v, np.generic):
            return {"t": "np", "a": self.array(np.asarray(v))}
        if type(v) in (list, tuple):
            return {"t": type(v).__name__, "v": [self.node(x) for x in v]}
        if type(v) is dict:
            return {"t": "dict", "v": [[self.node(k), self.node(x)] for k, x in v.items()]}
        cls = type(v)
        if known_classes().get(cls.__name__) is not cls:
            raise TypeError(f"checkpoint: cannot save an object of type {cls.__module__}.{cls.__qualname__}")
        if isinstance(v, enum.Enum):
            return {"t": "enum", "c": cls.__name__, "v": self.node(v.value)}
        return {"t": "obj", "c": cls.__name__, "f": {a: self.node(getattr(v, a)) for a in _attributes(cls)}}


def encode(payload):
    """Bytes of an ``.npz`` holding ``payload`` (see the module docstring)."""
    enc = _Encoder()
    structure = json.dumps({"format": FORMAT, "root": enc.node(payload)}, allow_nan=True).encode()
    buf = io.BytesIO()
    np.savez(buf, **enc.arrays, **{STRUCTURE: np.frombuffer(structure, dtype=np.uint8)})
    return buf.getvalue()


class _Decoder:
    def __init__(self, npz):
        self.npz = npz
        self.arrays = {}

    def array(self, name):
        if not isinstance(name, str) or name == STRUCTURE or name not in self.npz.files:
            raise FormatError(f"no array {name!r}")
        if name not in self.arrays:
            self.arrays[name] = self.npz[name]
        return self.arrays[name]

    def node(self, n):
        if n is None or isinstance(n, (bool, str, int, float)):
            return n
        if not isinstance(n, dict) or not isinstance(n.get("t"), str):
            raise FormatError(f"not a node: {str(n)[:60]}")
        t = n["t"]
        if t in ("list", "tuple"):
            items = [self.node(x) for x in _list(n.get("v"))]
            return items if t == "list" else tuple(items)
        if t == "dict":
            out = {}
            for pair in _list(n.get("v")):
                if not isinstance(pair, list) or len(pair) != 2:
                    raise FormatError("a dict item is not a [key, value] pair")
                key = self.node(pair[0])
                try:
                    out[key] = self.node(pair[1])
                except TypeError:
                    raise FormatError("unhashable dict key") from None
            return out
        if t == "nd":
            a = self.array(n.get("a"))
            if n.get("ro") is True:
                a.setflags(write=False)
            return a
        if t == "np":
            a = self.array(n.get("a"))
            if a.ndim != 0:
                raise FormatError("a numpy scalar that is not 0-d")
            return a[()]
        if t in ("enum", "obj"):
            cls = known_classes().get(n.get("c")) if isinstance(n.get("c"), str) else None
            if cls is None:
                raise FormatError(f"unknown class {str(n.get('c'))[:60]!r}")
            if t == "enum":
                if not issubclass(cls, enum.Enum):
                    raise FormatError(f"{cls.__name__} is not an enum")
                try:
                    return cls(self.node(n.get("v")))
                except (ValueError, TypeError):
                    raise FormatError(f"no {cls.__name__} {str(n.get('v'))[:60]!r}") from None
            if issubclass(cls, enum.Enum):
                raise FormatError(f"{cls.__name__} is an enum")
            fields = n.get("f")
            names = _attributes(cls)
            if not isinstance(fields, dict) or set(fields) != set(names):
                raise FormatError(f"the fields of {cls.__name__} do not match")
            obj = object.__new__(cls)
            for a in names:
                object.__setattr__(obj, a, self.node(fields[a]))
            return obj
        raise FormatError(f"unknown type tag {t[:60]!r}")


def _list(v):
    if not isinstance(v, list):
        raise FormatError("a list or dict node without a list of items")
    return v


def decode(data):
    """The payload of bytes written by :func:`encode`; FormatError for anything else
    (no pickle is ever loaded, no constructor of a class is called)."""
    try:
        npz = np.load(io.BytesIO(data), allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - not an npz at all
        raise FormatError(f"not a checkpoint .npz ({type(exc).__name__}: {exc})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise FormatError("not a checkpoint .npz (a single array)")
    with npz:
        try:
            raw = npz[STRUCTURE] if STRUCTURE in npz.files else None
            if raw is None or raw.dtype != np.uint8 or raw.ndim != 1:
                raise FormatError("no checkpoint structure in the .npz")
            doc = json.loads(raw.tobytes().decode("utf-8"))
            if not isinstance(doc, dict) or doc.get("format") != FORMAT:
                raise FormatError(f"not a checkpoint of format {FORMAT}")
            return _Decoder(npz).node(doc.get("root"))
        except FormatError:
            raise
        except RecursionError:
            raise FormatError("structure nested too deeply") from None
        except Exception as exc:  # noqa: BLE001 - any malformed content is one FormatError
            raise FormatError(f"{type(exc).__name__}: {exc}") from None
