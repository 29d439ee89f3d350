"""A seeded mutator of input files, and the check that every loader either succeeds or
raises its documented error (issue 16: no traceback from any input).

File kinds and their documented errors (all ``ValueError`` subclasses whose message
names the file):

- ``model``: a model file (YAML) -> :func:`openfdk.model.modelfile.load_model` raises
  :class:`~openfdk.model.model.ModelError`;
- ``subject``: a subject folder's ``subject.yaml`` -> :func:`openfdk.mandible.subject.load_subject`
  raises :class:`~openfdk.mandible.subject.SubjectError`;
- ``study``: a study file -> :func:`openfdk.study.spec.load_study` raises
  :class:`~openfdk.study.spec.StudyError` (a case's model is checked while loading);
- ``c3d``: a C3D trial -> :func:`openfdk.io.c3d.read_c3d` raises
  :class:`~openfdk.io.c3d.C3DError`;
- ``trc``: a TRC trial -> :func:`openfdk.io.trc.read_trc` raises
  :class:`~openfdk.io.trc.TRCError` (text mutations, as for YAML files, plus numbers
  replaced).

Mutations of YAML files act on the parsed tree (a value replaced by one of another type
or magnitude, scaled by 1000 or 1/1000 as a unit mistake would, negated, a key deleted,
misspelt or added, a unit changed, a list shortened or lengthened) or on the text (cut
short, a line repeated — a duplicate key — or dropped, a byte changed). C3D mutations act
on the bytes (bytes changed, header and parameter words set to edge values, floats set
to NaN or huge, the file cut short or lengthened).
"""

from __future__ import annotations

import shutil
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import yaml

KINDS = ("model", "subject", "study", "c3d", "trc")

_VALUES = (None, True, False, 0, -1, 1, 2, 5, 1.5, -2.5, 1e300, -1e300, 1e-300, float("nan"), float("inf"),
           "", "abc", "1e3", "m", "mm", "deg", [], {}, [1, 2], [0, 0, 0], [1, 2, 3, 4], [[1, 2, 3]], {"a": 1},
           "ground.origin", 10 ** 30, -(10 ** 30), "x" * 300)


# -- base inputs ----------------------------------------------------------------------

def base_model_dict():
    """A valid model file mapping exercising most sections: two bodies, a joint, markers,
    points, a measure, a driver-free FDK DOF, Hill and constant muscles, a ligament, a
    spring, a load, recruitment and FDK settings (lengths in mm, angles in deg)."""
    from ..fixtures.synthetic import two_body_model_dict

    d = two_body_model_dict()
    d["bodies"]["skull"]["points"] = {"o": [60.0, 0.0, 0.0], "lig": [0.0, -50.0, 10.0]}
    d["bodies"]["jaw"]["points"] = {"i": [0.0, 0.0, -30.0], "lig": [-60.0, -50.0, 30.0]}
    d["measures"] = {"cond": {"type": "vector", "from": "skull.plane", "to": "jaw.condyle", "expressed_in": "skull.plane"}}
    d["fdk_dofs"] = {"n": {"measure": "cond", "component": 2, "initial": 0.0, "max_step": 0.5}}
    d["muscles"] = {
        "m1": {"path": ["skull.o", "jaw.i"], "max_isometric_force": 500.0, "optimal_fibre_length": 40.0,
               "tendon_slack_length": 20.0},
        "m2": {"path": ["skull.o", "jaw.i"], "strength": 200.0},
    }
    d["ligaments"] = {"l1": {"path": ["skull.lig", "jaw.lig"], "stiffness": 1000.0, "reference_strain": 0.02}}
    d["springs"] = {"s1": {"measure": "cond", "component": 0, "stiffness": 100.0, "rest_value": 0.0}}
    d["loads"] = {"bite": {"point": "jaw.i", "force": [0.0, 0.0, 10.0]}}
    d["recruitment"] = {"criterion": "polynomial", "power": 3}
    d["fdk"] = {"tolerance": 1.0e-3, "max_iterations": 20, "jacobian": "analytic"}
    d["analysis"] = {"marker_cutoff_hz": 8.0, "start": 0.0, "end": 0.5, "frames": 11}
    return d


_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def _dump(data):
    return yaml.dump(data, Dumper=_DUMPER, sort_keys=False, allow_unicode=True)


class Bases:
    """Valid base files of every kind in a temporary folder (removed by :meth:`close`)."""

    def __init__(self, kinds=KINDS):
        self.dir = Path(tempfile.mkdtemp(prefix="openfdk-fuzz-"))
        self.texts, self.paths = {}, {}
        if "model" in kinds or "study" in kinds:
            self.texts["model"] = _dump(base_model_dict())
            self.paths["model"] = self.dir / "model.yaml"
            self.paths["model"].write_text(self.texts["model"])
        if "study" in kinds:
            self.texts["study"] = _dump({
                "openfdk_study": 1, "name": "fuzz", "kind": "model", "models": {"a": "model.yaml"},
                "parameters": {"k": {"set": "ligaments.l1.stiffness", "scale": 1.0},
                               "f": {"set": "muscles.m1.max_isometric_force", "mode": "multiply"}},
                "grid": {"k": [500.0, 1000.0], "f": [1.0, 1.5]},
                "run": {"chunks": 1, "cutoff_hz": 6.0, "start": 0.0, "end": 0.5, "retries": 1},
            })
            self.paths["study"] = self.dir / "study.yaml"
        if "subject" in kinds:
            from ..mandible.generator import create_subject

            subject = Path(create_subject(self.dir / "subject", resolution="coarse"))
            self.paths["subject"] = subject / "subject.yaml"
            self.texts["subject"] = self.paths["subject"].read_text()
        if "c3d" in kinds:
            from ..io.c3d import write_c3d
            from ..fixtures.synthetic import synthetic_markers

            _, labels, x, _ = synthetic_markers(30, rate=100.0, noise=1e-4, gap=(2, 10, 14))
            self.paths["c3d"] = self.dir / "trial.c3d"
            write_c3d(self.paths["c3d"], labels, x, 100.0, units="mm")
            self.c3d_bytes = self.paths["c3d"].read_bytes()

        if "trc" in kinds:
            self.texts["trc"] = _trc_text()
            self.paths["trc"] = self.dir / "trial.trc"

    def close(self):
        shutil.rmtree(self.dir, ignore_errors=True)


def _trc_text():
    """A valid TRC file (tab separated, mm) of the synthetic two-body trial, 20 frames,
    with a gap of one marker."""
    from ..fixtures.synthetic import synthetic_markers

    t, labels, x, _ = synthetic_markers(20, rate=100.0, noise=1e-4, gap=(2, 5, 8))
    head = ["PathFileType\t4\t(X/Y/Z)\ttrial.trc",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"100\t100\t{len(t)}\t{len(labels)}\tmm\t100\t1\t{len(t)}",
            "Frame#\tTime\t" + "\t".join(f"{lab}\t\t" for lab in labels),
            "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(len(labels))), ""]
    rows = [f"{k + 1}\t{t[k]:.4f}\t" + "\t".join("" if not np.isfinite(v) else f"{1e3 * v:.4f}" for v in x[k].ravel())
            for k in range(len(t))]
    return "\n".join(head + rows) + "\n"


def mutate_text(text, rng):
    """A mutated copy of a text table: 1–3 line/character mutations or a number replaced
    by an edge value (NaN, inf, huge, negative, text)."""
    for _ in range(int(rng.integers(1, 4))):
        cells = text.split("\t")
        if rng.random() < 0.4 and len(cells) > 1:
            i = int(rng.integers(len(cells)))
            cells[i] = str(rng.choice(["NaN", "inf", "-1", "0", "1e308", "abc", "", "1e-320", "mm", "m", "7"]))
            text = "\t".join(cells)
        else:
            text = _text_mutation(text, rng)
    return text


# -- mutations ------------------------------------------------------------------------

def _paths(node, prefix=()):
    """Every (path, value) of a parsed YAML tree (path = tuple of keys / indices)."""
    out = [(prefix, node)]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, prefix + (i,))
    return out


def _set(root, path, value):
    node = root
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value


def _tree_mutation(data, rng):
    """Mutate the parsed tree ``data`` in place (or return a new root)."""
    paths = [p for p, _ in _paths(data) if p]
    if not paths:
        return rng.choice(_VALUES_LIST)
    path = paths[int(rng.integers(len(paths)))]
    parent = data
    for k in path[:-1]:
        parent = parent[k]
    value = parent[path[-1]]
    op = int(rng.integers(9))
    if op == 0:
        _set(data, path, _VALUES_LIST[int(rng.integers(len(_VALUES_LIST)))])
    elif op == 1 and isinstance(value, (int, float)) and not isinstance(value, bool):
        _set(data, path, value * float(rng.choice([1000.0, 0.001, 100.0, 0.01, -1.0, 1e6])))
    elif op == 2 and isinstance(parent, dict):
        del parent[path[-1]]
    elif op == 3 and isinstance(parent, dict) and isinstance(path[-1], str) and len(path[-1]) > 1:
        k = path[-1]
        cut = int(rng.integers(len(k)))
        parent[k[:cut] + k[cut + 1:]] = parent.pop(k)            # a misspelt key
    elif op == 4 and isinstance(parent, dict):
        parent[f"extra_{int(rng.integers(100))}"] = _VALUES_LIST[int(rng.integers(len(_VALUES_LIST)))]
    elif op == 5 and isinstance(value, list) and value:
        if rng.random() < 0.5:
            del value[int(rng.integers(len(value)))]
        else:
            value.append(value[int(rng.integers(len(value)))])
    elif op == 6 and isinstance(value, str):
        _set(data, path, str(rng.choice(["m", "cm", "mm", "deg", "rad", "in", value.upper(), value + "x", ""])))
    elif op == 7 and isinstance(value, dict) and value:
        k = list(value)[int(rng.integers(len(value)))]
        value[k] = _VALUES_LIST[int(rng.integers(len(_VALUES_LIST)))]
    else:
        _set(data, path, value if not isinstance(value, (int, float)) or isinstance(value, bool)
             else -value if value else 1e-12)
    return data


_VALUES_LIST = list(_VALUES)


def _text_mutation(text, rng):
    lines = text.splitlines(keepends=True)
    op = int(rng.integers(5))
    if op == 0:                                   # cut short
        return text[: int(rng.integers(len(text) + 1))]
    if op == 1 and lines:                         # a line repeated: often a duplicate key
        i = int(rng.integers(len(lines)))
        return "".join(lines[: i + 1] + [lines[i]] + lines[i + 1:])
    if op == 2 and lines:                         # a line dropped
        i = int(rng.integers(len(lines)))
        return "".join(lines[:i] + lines[i + 1:])
    if op == 3 and text:                          # a character replaced
        i = int(rng.integers(len(text)))
        return text[:i] + str(rng.choice(list(":-[]{}#&*!|>'\"%@` \t\n0.eE"))) + text[i + 1:]
    if lines:                                     # indentation changed
        i = int(rng.integers(len(lines)))
        return "".join(lines[:i] + [" " * int(rng.integers(1, 4)) + lines[i]] + lines[i + 1:])
    return text


def mutate_yaml(text, rng, n_mutations=None):
    """A mutated copy of YAML ``text`` (str): 1–3 tree or text mutations."""
    n = int(rng.integers(1, 4)) if n_mutations is None else n_mutations
    for _ in range(n):
        if rng.random() < 0.7:
            try:
                data = yaml.load(text, Loader=_LOADER)
            except (yaml.YAMLError, RecursionError):
                data = None
            if isinstance(data, (dict, list)):
                text = _dump(_tree_mutation(data, rng))
                continue
        text = _text_mutation(text, rng)
    return text


def mutate_bytes(data: bytes, rng, n_mutations=None) -> bytes:
    """A mutated copy of a binary file: 1–4 byte-level mutations (C3D: the header is
    block 1, the parameters from block 2, then the data)."""
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 5)) if n_mutations is None else n_mutations):
        op = int(rng.integers(7))
        if not b:
            b = bytearray(rng.integers(0, 256, size=int(rng.integers(1, 600)), dtype=np.uint8).tobytes())
            continue
        hot = int(rng.integers(min(len(b), 1024))) if rng.random() < 0.7 else int(rng.integers(len(b)))
        if op == 0:
            b[hot] = int(rng.integers(256))
        elif op == 1:                               # a 16-bit word set to an edge value
            v = int(rng.choice([0, 1, 0x7FFF, 0x8000, 0xFFFF, 2, 255, 256]))
            b[hot: hot + 2] = v.to_bytes(2, "little")
        elif op == 2:                               # a float set to NaN, inf, huge or negative
            f = float(rng.choice([np.nan, np.inf, -np.inf, 1e38, -1.0, 0.0, 1e-38]))
            b[hot: hot + 4] = np.float32(f).tobytes()
        elif op == 3:
            b = b[: int(rng.integers(len(b) + 1))]
        elif op == 4:
            b += rng.integers(0, 256, size=int(rng.integers(1, 1024)), dtype=np.uint8).tobytes()
        elif op == 5:
            del b[hot: hot + int(rng.integers(1, 64))]
        else:
            b[hot: hot] = rng.integers(0, 256, size=int(rng.integers(1, 64)), dtype=np.uint8).tobytes()
    return bytes(b)


# -- loaders and their documented errors ----------------------------------------------

def documented_error(kind):
    """The exception class a loader of ``kind`` raises for bad input."""
    if kind == "model":
        from ..model.model import ModelError

        return ModelError
    if kind == "subject":
        from ..mandible.subject import SubjectError

        return SubjectError
    if kind == "study":
        from ..study.spec import StudyError

        return StudyError
    if kind == "trc":
        from ..io.trc import TRCError

        return TRCError
    from ..io.c3d import C3DError

    return C3DError


def _load(kind, path):
    if kind == "model":
        from ..io.modelfile import load_model

        return load_model(path)
    if kind == "subject":
        from ..mandible.subject import load_subject

        return load_subject(path.parent)
    if kind == "study":
        from ..study.spec import load_study

        return load_study(path)
    if kind == "trc":
        from ..io.trc import read_trc

        return read_trc(path)
    from ..io.c3d import read_c3d

    return read_c3d(path)


def fuzz(kind, n, seed=0, bases=None, time_limit=None):
    """Load ``n`` mutated inputs of ``kind``; returns a dict with counts ``inputs``,
    ``loaded``, ``refused`` (documented error naming the file) and ``unexpected``
    (a list of (seed, repr of the exception) for anything else), and ``seconds``."""
    own = bases is None
    bases = bases or Bases((kind,))
    error = documented_error(kind)
    rng = np.random.default_rng(seed)
    target = bases.paths[kind]
    original = target.read_bytes() if target.exists() else None
    counts = {"kind": kind, "inputs": 0, "loaded": 0, "refused": 0, "unexpected": []}
    t0 = time.perf_counter()
    try:
        for i in range(n):
            if time_limit is not None and time.perf_counter() - t0 > time_limit:
                break
            if kind == "c3d":
                target.write_bytes(mutate_bytes(bases.c3d_bytes, rng))
            elif kind == "trc":
                target.write_text(mutate_text(bases.texts[kind], rng), encoding="utf-8")
            else:
                target.write_text(mutate_yaml(bases.texts[kind], rng), encoding="utf-8")
            counts["inputs"] += 1
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    with np.errstate(all="ignore"):
                        _load(kind, target)
                counts["loaded"] += 1
            except error as exc:
                msg = str(exc)
                if target.name not in msg and str(target.parent.name) not in msg:
                    counts["unexpected"].append((seed, i, f"message does not name the file: {msg[:200]}"))
                else:
                    counts["refused"] += 1
            except Exception as exc:  # noqa: BLE001 - this is what the fuzz looks for
                counts["unexpected"].append((seed, i, f"{type(exc).__name__}: {str(exc)[:200]}"))
    finally:
        if original is not None:
            target.write_bytes(original)
        if own:
            bases.close()
    counts["seconds"] = time.perf_counter() - t0
    return counts


def reproduce(kind, seed, index, bases):
    """The mutated input number ``index`` of a :func:`fuzz` run with ``seed`` (for
    debugging an unexpected exception): str for YAML kinds, bytes for C3D."""
    rng = np.random.default_rng(seed)
    out = None
    for _ in range(index + 1):
        out = (mutate_bytes(bases.c3d_bytes, rng) if kind == "c3d" else mutate_text(bases.texts[kind], rng)
               if kind == "trc" else mutate_yaml(bases.texts[kind], rng))
    return out


def main(argv=None):
    """``python -m openfdk.bench.fuzz_inputs [N] [SEED] [KIND ...]``: the long fuzz run;
    prints one line of counts per kind and exits 1 on any unexpected exception."""
    import sys

    args = list(sys.argv[1:] if argv is None else argv)
    n = int(args.pop(0)) if args else 10_000
    seed = int(args.pop(0)) if args else 0
    kinds = args or list(KINDS)
    bad = 0
    bases = Bases(kinds)
    try:
        for kind in kinds:
            c = fuzz(kind, n, seed, bases)
            bad += len(c["unexpected"])
            print(f"{kind}: {c['inputs']} mutated inputs, {c['loaded']} loaded, {c['refused']} refused with "
                  f"{documented_error(kind).__name__}, {len(c['unexpected'])} unexpected, {c['seconds']:.0f} s "
                  f"({c['inputs'] / max(c['seconds'], 1e-9):.0f} inputs/s)", flush=True)
            for u in c["unexpected"][:20]:
                print(f"  unexpected (seed {u[0]}, input {u[1]}): {u[2]}", flush=True)
    finally:
        bases.close()
    return 1 if bad else 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())


