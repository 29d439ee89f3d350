"""Study files -> a list of independent cases (format: docs/studies.md).

A study file (YAML, safe loader, nothing evaluated) names its inputs (for the ``model``
kind: ``models`` and optional ``trials``), its parameters (each a name for one or more
dotted override paths, :mod:`.overrides`), a ``grid`` (Cartesian product of values)
and/or a list of ``cases`` (explicit parameter sets), and ``run`` options shared by
every case. Cases = input combinations × parameter sets, in file order.

Each case gets a stable id (``<model>-<trial>-<k>``, k the parameter-set index) and a
*fingerprint*: a SHA-256 of its definition (kind, inputs, overrides, the run options
that change results) and of the content of its input files. A case folder whose
``case.json`` holds the same fingerprint is complete and is not run again.
"""

from __future__ import annotations

import difflib
import hashlib
import itertools
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from ..io import limits
from ..io.yamlfile import YamlContext, read_yaml

from .defaults import DEFAULT_OVERLAP, DEFAULT_RETRIES
from .kinds import CASE_KINDS, import_callable
from .overrides import Override, OverrideError, apply_overrides

FORMAT_VERSION = 1
TOP_LEVEL = ("openfdk_study", "name", "description", "kind", "parameters", "grid", "cases", "run")
RUN_KEYS = ("chunks", "overlap", "cutoff_hz", "start", "end", "metrics", "retries")


class StudyError(ValueError):
    """A malformed study file; the message names the file and the entry."""


@dataclass(frozen=True)
class RunOptions:
    """Options of every case: chunks (segments of one trial, >= 1); overlap (frames of
    warm-up solved before each segment and dropped, >= 0); cutoff_hz (marker low-pass,
    Hz; None = the model's); start, end (analysed time window, s; None = the model's /
    whole trial); metrics (extra result columns summarised per case); retries (runs of a
    failing case after the first)."""

    chunks: int = 1
    overlap: int = DEFAULT_OVERLAP
    cutoff_hz: float | None = None
    start: float | None = None
    end: float | None = None
    metrics: tuple = ()
    retries: int = DEFAULT_RETRIES

    def result_defining(self):
        """The options that change a case's results (part of its fingerprint)."""
        return {"chunks": self.chunks, "overlap": self.overlap if self.chunks > 1 else None,
                "cutoff_hz": self.cutoff_hz, "start": self.start, "end": self.end}


@dataclass(frozen=True)
class Parameter:
    """A named study parameter: the dotted override ``paths`` it sets; the model gets
    value × ``scale`` (the summary shows the value as written); ``mode`` "set" or
    "multiply" (the value is a factor on the existing number)."""

    name: str
    paths: tuple
    scale: float = 1.0
    mode: str = "set"


@dataclass(frozen=True)
class Case:
    """One independent task. case_id : folder name; kind, prepare : see
    :class:`~.kinds.CaseKind`; names : input section -> entry name; inputs : input
    section -> value (absolute path for path inputs); parameters : parameter -> value as
    written in the study; overrides : tuple of Override; options : RunOptions;
    fingerprint : hex SHA-256 (module docstring)."""

    case_id: str
    kind: str
    prepare: str
    names: dict
    inputs: dict
    parameters: dict
    overrides: tuple
    options: RunOptions
    fingerprint: str = ""
    #: ImportOptions of an ``.osim`` model given on the command line (``openfdk run
    #: --chunks``; :func:`openfdk.io.opensim.overlay.registered_options`), or None
    import_options: object = None


@dataclass(frozen=True)
class Study:
    """A loaded study: name; source (the study file, or None); kind; parameters; cases;
    options; data (the parsed mapping, for the record)."""

    name: str
    source: Path | None
    kind: str
    parameters: tuple
    cases: tuple
    options: RunOptions
    data: dict = field(default_factory=dict)

    @property
    def parameter_names(self):
        """Every parameter name or direct path used by some case, in first-use order."""
        names = []
        for c in self.cases:
            names += [k for k in c.parameters if k not in names]
        return names


class _Ctx(YamlContext):
    """The shared YAML context (:class:`~openfdk.io.yamlfile.YamlContext`) raising
    :class:`StudyError`."""

    error_type = StudyError


_SAFE = re.compile(r"[^A-Za-z0-9_.=+-]+")


def safe_name(text) -> str:
    """A file-system safe version of ``text`` (letters, digits, _ . = + -)."""
    s = _SAFE.sub("_", str(text)).strip("._")
    return s or "case"


def _entries(ctx, value, section, is_path, base_dir):
    """name -> value of an input section (a mapping, a list, or one value)."""
    if isinstance(value, dict):
        items = [(str(k), v) for k, v in value.items()]
    elif isinstance(value, list):
        items = [((Path(str(v)).stem if is_path else str(v)), v) for v in value]
    elif isinstance(value, (str, int, float)):
        items = [((Path(str(value)).stem if is_path else str(value)), value)]
    else:
        raise ctx.error(section, f"expected a mapping name -> value or a list, got {type(value).__name__}")
    if not items:
        raise ctx.error(section, "is empty")
    out = {}
    for name, v in items:
        if name in out:
            raise ctx.error(section, f"entry name {name!r} is used twice; give the entries names (a mapping)")
        if is_path:
            if not isinstance(v, str):
                raise ctx.error(f"{section}.{name}", f"expected a file or folder path, got {v!r}")
            try:
                p = (base_dir / v).resolve()
                found = p.exists()
            except (OSError, ValueError) as exc:  # name too long, NUL byte
                raise ctx.error(f"{section}.{name}", f"{v[:80]!r} is not a usable path: {exc}") from None
            if not found:
                raise ctx.error(f"{section}.{name}", f"{v!r} not found (relative to {str(base_dir)!r})")
            v = str(p)
        out[name] = v
    return out


def _parameters(ctx, data):
    params = {}
    for name, spec in ctx.mapping(data or {}, "parameters").items():
        where = f"parameters.{name}"
        if "." in str(name):
            raise ctx.error(where, "a parameter name must not contain '.' (dotted keys are override paths)")
        if isinstance(spec, (str, list)):
            spec = {"set": spec}
        ctx.keys(spec, where, ("set", "scale", "mode"))
        paths = spec.get("set")
        paths = [paths] if isinstance(paths, str) else paths
        if not isinstance(paths, list) or not paths or not all(isinstance(p, str) and p for p in paths):
            raise ctx.error(f"{where}.set", f"expected a dotted path or a list of them, got {spec.get('set')!r}")
        scale = ctx.number(spec.get("scale", 1.0), f"{where}.scale")
        mode = ctx.choice(spec.get("mode", "set"), f"{where}.mode", ("set", "multiply"), "mode")
        params[str(name)] = Parameter(str(name), tuple(paths), float(scale), mode)
    return params


def _parameter_sets(ctx, data, params, n_inputs=1):
    """[{parameter or path: value}] from ``grid`` (product, last varies fastest) then
    ``cases``. ``n_inputs`` (the number of input combinations) times the number of sets
    is checked against :data:`openfdk.io.limits.STUDY_CASES` before the sets are made."""
    sets = []
    grid = data.get("grid")
    if grid is not None:
        if not isinstance(grid, dict) or not grid:
            raise ctx.error("grid", "expected a mapping parameter -> list of values")
        for k, values in grid.items():
            if not isinstance(values, list) or not values:
                raise ctx.error(f"grid.{k}", f"expected a non-empty list of values, got {values!r}")
    listed = data.get("cases")
    if listed is not None:
        if not isinstance(listed, list) or not all(isinstance(c, dict) for c in listed):
            raise ctx.error("cases", "expected a list of mappings parameter -> value")
    _check_case_count(ctx, grid, listed, n_inputs)
    if grid is not None:
        keys = [str(k) for k in grid]
        sets += [dict(zip(keys, combo)) for combo in itertools.product(*grid.values())]
    if listed is not None:
        sets += [{str(k): v for k, v in c.items()} for c in listed]
    for i, s in enumerate(sets):
        for k in s:
            if k not in params and "." not in k:
                close = difflib.get_close_matches(k, list(params), n=1)
                hint = f"; did you mean {close[0]!r}?" if close else f"; declared: {list(params)}"
                where = f"grid.{k}" if grid is not None and k in grid else f"cases[{i}].{k}"
                raise ctx.error(where, "unknown parameter (not declared under 'parameters' and not a dotted "
                                       f"path){hint}")
    return sets


def _check_case_count(ctx, grid, listed, n_inputs):
    """Refuse a study of more than :data:`openfdk.io.limits.STUDY_CASES` cases, naming
    the grid (or the case list, or the inputs) and how the count comes about."""
    n_grid = math.prod(len(v) for v in grid.values()) if grid else 0
    n_listed = len(listed) if listed else 0
    n_sets = n_grid + n_listed
    total = n_inputs * max(1, n_sets)
    if total <= limits.STUDY_CASES:
        return
    entry = "grid" if n_grid else "cases" if n_listed else ""
    parts = ([" × ".join(str(len(v)) for v in grid.values()) + " grid points"] if n_grid else []) + \
        ([f"{n_listed} listed cases"] if n_listed else [])
    how = f"{n_inputs} input combination{'s' if n_inputs != 1 else ''}" + (f" × ({' + '.join(parts)})" if parts else "")
    limits.check_count(total, "STUDY_CASES", ctx.source, entry, f"cases ({how})", StudyError)


def _overrides(pset, params):
    out = []
    for key, value in pset.items():
        p = params.get(key)
        if p is None:
            out.append(Override(key, value, "set"))
            continue
        v = value
        if p.scale != 1.0:
            try:  # YAML 1.1 reads 1.0e10 (no sign in the exponent) as a string
                number = float(value) if isinstance(value, str) else value
            except ValueError:
                number = None
            if isinstance(number, bool) or not isinstance(number, (int, float)):
                raise StudyError(f"parameter {key!r} has scale {p.scale}; its values must be numbers, got {value!r}")
            v = number * p.scale
        out += [Override(path, v, p.mode) for path in p.paths]
    return tuple(out)


def _run_options(ctx, data):
    run = ctx.keys(data or {}, "run", RUN_KEYS)

    def integer(key, default, minimum):
        return ctx.integer(run.get(key, default), f"run.{key}", low=minimum)

    def number(key, unit):
        v = run.get(key)
        return None if v is None else ctx.number(v, f"run.{key}", unit)

    start, end = number("start", "s"), number("end", "s")
    if start is not None and end is not None and start > end:
        raise ctx.error("run", f"start ({start:g} s) is after end ({end:g} s)")

    metrics = run.get("metrics", [])
    if isinstance(metrics, str):
        metrics = [metrics]
    if not isinstance(metrics, list) or not all(isinstance(m, str) for m in metrics):
        raise ctx.error("run.metrics", f"expected a list of result column names, got {metrics!r}")
    return RunOptions(integer("chunks", 1, 1), integer("overlap", DEFAULT_OVERLAP, 0), number("cutoff_hz", "Hz"),
                      start, end, tuple(metrics), integer("retries", DEFAULT_RETRIES, 0))


_DIGESTS: dict = {}


def content_digest(path) -> str:
    """SHA-256 of a file's bytes, or of a folder's files (relative names and bytes)."""
    p = Path(path)
    st = p.stat()
    key = (str(p), st.st_mtime_ns, st.st_size)
    if key in _DIGESTS:
        return _DIGESTS[key]
    h = hashlib.sha256()
    files = [p] if p.is_file() else sorted(f for f in p.rglob("*") if f.is_file())
    for f in files:
        h.update(str(f.relative_to(p) if f != p else f.name).encode())
        with open(f, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    _DIGESTS[key] = h.hexdigest()
    return _DIGESTS[key]


def case_fingerprint(kind, inputs, paths, overrides, options) -> str:
    """Hex SHA-256 of what defines a case's results (module docstring)."""
    doc = {
        "kind": kind,
        "inputs": {s: (content_digest(v) if s in paths else v) for s, v in sorted(inputs.items())},
        "overrides": [[o.path, o.value, o.mode] for o in overrides],
        "options": options.result_defining(),
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def study_from_dict(data, source="<study>", base_dir=".", check_overrides=True) -> Study:
    """Build a :class:`Study` from a parsed study mapping; paths are relative to
    ``base_dir``. With ``check_overrides`` (and a kind whose prepare is cheap), every
    override path is resolved against every input's model mapping first, so a path that
    matches nothing is reported before anything runs."""
    ctx = _Ctx(source)
    base_dir = Path(base_dir)
    if not isinstance(data, dict):
        raise StudyError(f"{source}: a study file must contain a mapping (sections {list(TOP_LEVEL)} ...)")
    version = data.get("openfdk_study", FORMAT_VERSION)
    if isinstance(version, bool) or version != FORMAT_VERSION:  # `openfdk_study: true` is not version 1
        raise ctx.error("openfdk_study", f"unsupported version {version!r}; this openfdk reads {FORMAT_VERSION}")
    kind_name = data.get("kind", "model")
    kind = CASE_KINDS.get(kind_name) if isinstance(kind_name, str) else None
    if kind is None:
        raise ctx.error("kind", f"unknown case kind {kind_name!r}; known: {sorted(CASE_KINDS)}")
    ctx.keys(data, "", TOP_LEVEL + tuple(kind.inputs))
    inputs = {}
    for section in kind.inputs:
        if section not in data or data[section] is None:
            if section in kind.optional:
                continue
            raise ctx.error("", f"missing section {section!r} (kind {kind.name!r} needs {list(kind.inputs)})")
        inputs[section] = _entries(ctx, data[section], section, section in kind.paths, base_dir)
    params = _parameters(ctx, data.get("parameters"))
    psets = _parameter_sets(ctx, data, params, math.prod(len(v) for v in inputs.values()))
    options = _run_options(ctx, data.get("run"))
    sections = list(inputs)
    combos = list(itertools.product(*[list(inputs[s].items()) for s in sections]))
    width = max(3, len(str(max(len(psets) - 1, 0))))
    prepare = import_callable(kind.prepare) if (check_overrides and kind.cheap_prepare) else None
    cases, seen = [], set()
    for combo in combos:
        names = {s: name for s, (name, _) in zip(sections, combo)}
        values = {s: value for s, (_, value) in zip(sections, combo)}
        prepared = None
        for k, pset in enumerate(psets or [{}]):
            parts = [safe_name(n) for n in names.values()] + ([f"{k:0{width}d}"] if psets else [])
            case_id = "-".join(parts)
            if case_id in seen:
                raise ctx.error("", f"two cases get the id {case_id!r}; give the inputs distinct names")
            seen.add(case_id)
            try:
                overrides = _overrides(pset, params)
            except (StudyError, OverrideError) as exc:
                raise ctx.error(f"case {case_id}", str(exc)) from None
            case = Case(case_id, kind.name, kind.prepare, names, values, dict(pset), overrides, options)
            if prepare is not None and overrides:
                if prepared is None:
                    try:
                        prepared = prepare(case)
                    except ValueError as exc:  # the input's model file is bad (ModelError)
                        raise ctx.error(f"case {case_id}", str(exc)) from None
                try:
                    apply_overrides(prepared.model_data, overrides, source=prepared.source)
                except OverrideError as exc:
                    raise ctx.error(f"case {case_id}", str(exc)) from None
            fp = case_fingerprint(kind.name, values, kind.paths, overrides, options)
            cases.append(Case(case_id, kind.name, kind.prepare, names, values, dict(pset), overrides, options, fp))
    name = str(data.get("name", Path(str(source)).stem))
    return Study(name, None, kind.name, tuple(params.values()), tuple(cases), options, data)


def load_study(path, check_overrides=True) -> Study:
    """Read and validate a study file; paths in it are relative to its folder."""
    path = Path(path)
    data = read_yaml(path, StudyError, "study file")
    study = study_from_dict(data, path.name, path.parent.resolve(), check_overrides)
    return Study(study.name, path.resolve(), study.kind, study.parameters, study.cases, study.options, study.data)
