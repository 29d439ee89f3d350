"""YAML model files -> :class:`~openfdk.model.model.Model` (format: docs/model-file.md).

The file is data: it is read with PyYAML's safe loader and nothing in it is evaluated.
Lengths are in the file's declared unit (``units.length``: m, cm or mm) and angles in
``units.angle`` (rad or deg); they are converted to SI once, here. Every error names
the file and the entry, e.g. ``model.yaml: bodies.jaw.mass: expected a number``.

This module reads the core sections (units, bodies, measures, joints, constraints,
drivers, FDK DOFs, analysis). The force-element, contact and FDK-settings sections
belong to later layers; :mod:`openfdk.io.modelfile` reads a whole file by calling the
core and then each section's loader explicitly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from ..io.yamlfile import YamlContext

from . import names
from .builder import ModelBuilder
from .orientation_entry import _orientation
from .coordinates_section import finish_coordinates, load_couplers, load_custom_joint, read_coordinates
from .components import GROUND
from .measures import Linear
from .model import Model, ModelError
from .timefunctions import Constant, Fourier, Polynomial, SplineThroughData

LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
ANGLE_UNITS = {"rad": 1.0, "deg": np.pi / 180.0}
FORMAT_VERSION = 1

CORE_SECTIONS = (
    "openfdk", "name", "units", "gravity", "bodies", "measures", "joints",
    "constraints", "drivers", "fdk_dofs", "analysis", "description", "coordinates", "couplers",
    "tasks",
)


#: sections whose keys are names of model items (bodies, elements, …); those names end up
#: in file names and XML of exports (export-opensim), so they are checked at load
NAMED_SECTIONS = ("bodies", "measures", "joints", "constraints", "drivers", "fdk_dofs", "coordinates", "couplers",
                  "muscles", "ligaments", "springs", "bushings", "contacts", "loads", "reactions", "wrapping",
                  "actuators")
#: the rule for names (shared with models built in Python): :mod:`openfdk.model.names`
NAME_FORBIDDEN = names.NAME_FORBIDDEN
name_problem = names.name_problem


def _check_names(data, ctx):
    """Refuse names (keys of :data:`NAMED_SECTIONS`, and of a body's frames, points and
    markers) that :func:`name_problem` rejects, naming the entry."""
    for section in NAMED_SECTIONS:
        items = data.get(section)
        if not isinstance(items, dict):
            continue
        for name, spec in items.items():
            problem = name_problem(name)
            if problem:
                raise ctx.error(f"{section}.{name}", problem)
            if section == "bodies" and isinstance(spec, dict):
                for sub in ("frames", "points", "markers"):
                    for sname in (spec.get(sub) or {}) if isinstance(spec.get(sub), dict) else ():
                        problem = name_problem(sname)
                        if problem:
                            raise ctx.error(f"bodies.{name}.{sub}.{sname}", problem)


class Ctx(YamlContext):
    """Where we are in the file (for messages) and the unit scales: the shared YAML
    context (:class:`~openfdk.io.yamlfile.YamlContext`) raising :class:`ModelError`."""

    error_type = ModelError

    def __init__(self, source, length=1.0, angle=1.0, base_dir=None):
        super().__init__(source, length, angle, base_dir)


def read_core(data, source="<dict>", base_dir=None, sections=()):
    """(ModelBuilder, Ctx) after the core sections of a parsed model file; ``sections``
    are the names of the further sections the caller reads (any other top-level key is
    an error naming it)."""
    ctx = Ctx(source, base_dir=base_dir)
    if not isinstance(data, dict):
        raise ModelError(f"{source}: the file must contain a mapping with sections {list(CORE_SECTIONS)}")
    ctx.keys(data, "(top level)", list(CORE_SECTIONS) + list(sections), required=("bodies",))
    _check_names(data, ctx)
    version = data.get("openfdk", FORMAT_VERSION)
    if isinstance(version, bool) or version != FORMAT_VERSION:  # `openfdk: true` is not version 1
        raise ctx.error("openfdk", f"unsupported format version {version!r}; this openfdk reads version {FORMAT_VERSION}")
    units = ctx.keys(data.get("units", {}) or {}, "units", ["length", "angle"])
    lu, au = units.get("length", "m"), units.get("angle", "rad")
    ctx.choice(lu, "units.length", LENGTH_UNITS, "length unit")
    ctx.choice(au, "units.angle", ANGLE_UNITS, "angle unit")
    ctx.length, ctx.angle = LENGTH_UNITS[lu], ANGLE_UNITS[au]
    gravity = ctx.vector(data.get("gravity", [0, 0, -9.81]), "gravity", n=3)
    b = ModelBuilder(str(data.get("name", source)), gravity=gravity)
    b.source = source
    _load_bodies(b, data["bodies"], ctx)
    for name, spec in (ctx.mapping(data.get("measures") or {}, "measures")).items():
        _wrap(ctx, f"measures.{name}", lambda: b.add_measure(name, _measure(b, spec, f"measures.{name}", ctx)))
    coordinates = read_coordinates(data.get("coordinates"), ctx)
    waiting = []  # custom joints whose coordinate follows a coupler of a coordinate not yet moved
    for name, spec in (ctx.mapping(data.get("joints") or {}, "joints")).items():
        if isinstance(spec, dict) and spec.get("type") == "custom":
            if not load_custom_joint(b, name, spec, coordinates, ctx, _wrap, data.get("couplers"), last_try=False):
                waiting.append((name, spec))
        else:
            _load_joint(b, name, spec, ctx)
    while waiting:
        left = [(n, s) for n, s in waiting
                if not load_custom_joint(b, n, s, coordinates, ctx, _wrap, data.get("couplers"), last_try=False)]
        if len(left) == len(waiting):  # no progress: name the first one's coupler
            load_custom_joint(b, *left[0], coordinates, ctx, _wrap, data.get("couplers"))
        waiting = left
    finish_coordinates(b, coordinates, ctx, _wrap)
    load_couplers(b, data.get("couplers"), coordinates, ctx, _wrap)
    for name, spec in (ctx.mapping(data.get("constraints") or {}, "constraints")).items():
        _load_constraint(b, name, spec, ctx)
    for name, spec in (ctx.mapping(data.get("drivers") or {}, "drivers")).items():
        _load_driver(b, name, spec, ctx)
    for name, spec in (ctx.mapping(data.get("fdk_dofs") or {}, "fdk_dofs")).items():
        _load_fdk(b, name, spec, ctx)
    from .tasks import load_tasks

    load_tasks(b, data.get("tasks"), ctx, lambda spec, path: _measure(b, spec, path, ctx),
               lambda spec, units, path: _function(spec, units, path, ctx), _wrap)
    b.elements["analysis"] = _analysis(data.get("analysis") or {}, ctx)
    b.elements["units"] = {"length": lu, "angle": au}
    return b, ctx


def build(b, ctx) -> Model:
    """The validated Model of a builder filled from a file (errors name the file)."""
    return _wrap(ctx, "(model)", b.build)


def _analysis(spec, ctx):
    """The ``analysis`` section: marker_cutoff_hz (Hz, >= 0), start and end (s, start <=
    end) and frames (an integer >= 1) or rate_hz (determinate frames every 1/rate_hz s
    from start: the samples of a ``--motion`` file)."""
    spec = ctx.keys(spec, "analysis", ["marker_cutoff_hz", "start", "end", "frames", "rate_hz"])
    out = {}
    if "marker_cutoff_hz" in spec:
        out["marker_cutoff_hz"] = ctx.number(spec["marker_cutoff_hz"], "analysis.marker_cutoff_hz", "Hz", nonnegative=True)
    for k in ("start", "end"):
        if k in spec:
            out[k] = ctx.number(spec[k], f"analysis.{k}", "s")
    if "start" in out and "end" in out and out["start"] > out["end"]:
        raise ctx.error("analysis", f"start ({out['start']:g} s) is after end ({out['end']:g} s)")
    if "frames" in spec:
        out["frames"] = ctx.integer(spec["frames"], "analysis.frames", low=1, high=10_000_000)
    if "rate_hz" in spec:
        if "frames" in spec:
            raise ctx.error("analysis", "give frames or rate_hz, not both")
        out["rate_hz"] = ctx.number(spec["rate_hz"], "analysis.rate_hz", "Hz", positive=True, high=1e6)
    return out


def _wrap(ctx, path, fn):
    """Run fn, re-raising builder errors with the file and entry path."""
    try:
        return fn()
    except ValueError as exc:  # ModelError, and the parameter errors of muscles, ligaments, meshes
        msg = str(exc)
        if isinstance(exc, ModelError) and msg.startswith(ctx.source):
            raise
        raise ctx.error(path, msg) from None


def _load_bodies(b, bodies, ctx):
    ctx.mapping(bodies, "bodies")
    if not bodies:
        raise ctx.error("bodies", "at least one body is needed")
    for name, spec in bodies.items():
        p = f"bodies.{name}"
        ctx.keys(spec, p, ["mass", "inertia", "position", "orientation", "fixed", "equilibrium", "frames", "points", "markers",
                         "visual", "inertia_as_given"])
        if name == GROUND:
            ctx.keys(spec, p, ["fixed", "frames", "points", "visual"])
            if spec.get("fixed", True) is not True:
                raise ctx.error(f"{p}.fixed", "the ground is always fixed")
            spec = {k: v for k, v in spec.items() if k != "fixed"}
        fixed = ctx.boolean(spec.get("fixed", False), f"{p}.fixed") or name == GROUND
        if not fixed and name != GROUND and "mass" not in spec:
            raise ctx.error(p, "missing required key 'mass' (kg)")
        mass = ctx.number(spec.get("mass", 0.0), f"{p}.mass", nonnegative=True)
        inertia = spec.get("inertia", [0, 0, 0] if (fixed or name == GROUND) else None)
        if inertia is None:
            raise ctx.error(p, "missing required key 'inertia' (kg m², 3 principal moments or a 3x3 matrix)")
        inertia = ctx.vector(inertia, f"{p}.inertia")
        R = _orientation(spec.get("orientation"), f"{p}.orientation", ctx)
        if name != GROUND:
            _wrap(ctx, p, lambda: b.add_body(
                name, mass, inertia, ctx.position(spec.get("position", [0, 0, 0]), f"{p}.position"), R,
                fixed=fixed, equilibrium=ctx.boolean(spec.get("equilibrium", not fixed), f"{p}.equilibrium"),
                inertia_as_given=ctx.boolean(spec.get("inertia_as_given", False), f"{p}.inertia_as_given")))
        for section in ("frames", "points"):
            for fname, fspec in (ctx.mapping(spec.get(section) or {}, f"{p}.{section}")).items():
                fp = f"{p}.{section}.{fname}"
                if isinstance(fspec, dict):
                    ctx.keys(fspec, fp, ["position", "orientation"], required=("position",))
                    pos, ori = fspec["position"], _orientation(fspec.get("orientation"), f"{fp}.orientation", ctx)
                else:
                    pos, ori = fspec, None
                _wrap(ctx, fp, lambda: b.add_frame(name, fname, ctx.position(pos, f"{fp}.position" if isinstance(fspec, dict) else fp), ori))
        for mname, mspec in (ctx.mapping(spec.get("markers") or {}, f"{p}.markers")).items():
            mp = f"{p}.markers.{mname}"
            if isinstance(mspec, dict):
                ctx.keys(mspec, mp, ["position", "weight", "label"], required=("position",))
                pos = ctx.position(mspec["position"], f"{mp}.position")
                weight = ctx.number(mspec.get("weight", 1.0), f"{mp}.weight", nonnegative=True)
                label = mspec.get("label")
            else:
                pos, weight, label = ctx.position(mspec, mp), 1.0, None
            _wrap(ctx, mp, lambda: b.add_marker(mname, name, pos, weight, label))
        if "visual" in spec:
            from .visuals import load_visuals

            load_visuals(b, name, spec["visual"], f"{p}.visual", ctx)


MEASURE_KEYS = {
    "point": ["point"],
    "vector": ["from", "to", "expressed_in"],
    "distance": ["from", "to"],
    "angles": ["frame", "of", "sequence"],
    "jcs": ["frame", "of", "joint", "side"],
    "axis_dot": ["frame_a", "axis_a", "frame_b", "axis_b"],
    "plane_distance": ["plane", "point"],
    "linear": ["terms", "offset"],
}


def _measure(b, spec, path, ctx):
    """A measure from its spec, or a reference to a named measure (a string)."""
    if isinstance(spec, str):
        return _wrap(ctx, path, lambda: b.measure(spec))
    ctx.mapping(spec, path)
    kind = spec.get("type")
    if not isinstance(kind, str) or kind not in MEASURE_KEYS:
        raise ctx.error(f"{path}.type", f"unknown measure type {kind!r}; expected one of {list(MEASURE_KEYS)}")
    ctx.keys(spec, path, ["type"] + MEASURE_KEYS[kind], required=[k for k in MEASURE_KEYS[kind] if k not in ("expressed_in", "offset", "sequence", "joint", "side")])
    if kind == "point":
        return _wrap(ctx, path, lambda: b.point(spec["point"]))
    if kind == "vector":
        return _wrap(ctx, path, lambda: b.vector(spec["from"], spec["to"], spec.get("expressed_in")))
    if kind == "distance":
        return _wrap(ctx, path, lambda: b.distance(spec["from"], spec["to"]))
    if kind == "angles":
        return _wrap(ctx, path, lambda: b.angles(spec["frame"], spec["of"], sequence=spec.get("sequence", "xyz")))
    if kind == "jcs":
        from .rotation_angles import JCS_CONVENTIONS

        joint = ctx.choice(spec.get("joint", "knee"), f"{path}.joint", sorted(JCS_CONVENTIONS), "joint convention")
        side = ctx.choice(spec.get("side", "right"), f"{path}.side", ["left", "right"], "side")
        return _wrap(ctx, path, lambda: b.jcs_angles(spec["frame"], spec["of"], joint, side))
    if kind == "axis_dot":
        return _wrap(ctx, path, lambda: b.axis_dot(
            spec["frame_a"], ctx.vector(spec["axis_a"], f"{path}.axis_a", n=3),
            spec["frame_b"], ctx.vector(spec["axis_b"], f"{path}.axis_b", n=3)))
    if kind == "plane_distance":
        return _wrap(ctx, path, lambda: b.plane_distance(spec["plane"], spec["point"]))
    terms = []
    if not isinstance(spec["terms"], list) or not spec["terms"]:
        raise ctx.error(f"{path}.terms", "expected a non-empty list of {measure, coefficients}")
    for k, term in enumerate(spec["terms"]):
        tp = f"{path}.terms[{k}]"
        ctx.keys(term, tp, ["measure", "coefficients"], required=("measure", "coefficients"))
        m = _measure(b, term["measure"], f"{tp}.measure", ctx)
        C = np.atleast_2d(ctx.vector(term["coefficients"], f"{tp}.coefficients"))
        if C.shape[1] != m.size:
            raise ctx.error(f"{tp}.coefficients", f"needs {m.size} columns (the measure's size), got {C.shape[1]}")
        terms.append((C, m))
    lin = _wrap(ctx, path, lambda: Linear(terms))
    if "offset" in spec:
        off = ctx.vector(spec["offset"], f"{path}.offset", n=lin.size)
        lin.offset = off * np.array([_unit_scale(u, ctx) for u in lin.units])
    return lin


def _unit_scale(unit, ctx):
    return ctx.length if unit == "length" else ctx.angle if unit == "angle" else 1.0


def _components(spec, m, path, ctx):
    comps = spec.get("components")
    if comps is None:
        return None, m.units
    if not isinstance(comps, list) or not all(isinstance(c, int) and not isinstance(c, bool) for c in comps):
        raise ctx.error(f"{path}.components", f"expected a list of component indices, got {comps!r}")
    bad = [c for c in comps if not 0 <= c < m.size]
    if bad:
        raise ctx.error(f"{path}.components", f"indices {bad} out of range for a measure of size {m.size}")
    return comps, tuple(m.units[c] for c in comps)


#: joint rows whose measure is a length (the others are cosines, dimensionless)
LENGTH_ROWS = ("x", "y", "z", "n")


def _load_joint(b, name, spec, ctx):
    """A joint; ``fdk`` (list of row labels, or label -> {initial, max_step,
    perturbation}) makes rows FDK DOFs, ``reaction`` (label -> bool) switches
    single rows' reactions (docs/model-file.md, joints)."""
    p = f"joints.{name}"
    ctx.keys(spec, p, ["type", "parent", "child", "normal", "fdk", "reaction"], required=("type", "parent", "child"))
    normal = ctx.vector(spec["normal"], f"{p}.normal", n=3) if "normal" in spec else None
    fdk = spec.get("fdk")
    if isinstance(fdk, dict):
        out = {}
        for label, settings in fdk.items():
            lp = f"{p}.fdk.{label}"
            settings = {} if settings is None else settings
            ctx.keys(settings, lp, ["initial"] + FDK_SETTING_KEYS)
            scale = ctx.length if label in LENGTH_ROWS else 1.0
            out[label] = {}
            for k in ("initial", "max_step", "perturbation"):
                if k in settings:
                    out[label][k] = ctx.number(settings[k], f"{lp}.{k}", positive=(k != "initial")) * scale
        fdk = out
    elif fdk is not None and not (isinstance(fdk, list) and all(isinstance(x, str) for x in fdk)):
        raise ctx.error(f"{p}.fdk", f"expected a list of row labels (e.g. [x, y]) or a mapping, got {fdk!r}")
    elif fdk is not None and len(set(fdk)) != len(fdk):
        dup = next(x for x in fdk if fdk.count(x) > 1)
        raise ctx.error(f"{p}.fdk", f"row {dup!r} is given twice")
    reaction = spec.get("reaction")
    if reaction is not None and not isinstance(reaction, dict):
        raise ctx.error(f"{p}.reaction", f"expected a mapping row label -> true/false, got {reaction!r}")
    _wrap(ctx, p, lambda: b.add_joint(name, spec["type"], spec["parent"], spec["child"], normal=normal,
                                      fdk=fdk, reaction=reaction))


def _load_constraint(b, name, spec, ctx):
    p = f"constraints.{name}"
    ctx.keys(spec, p, ["measure", "components", "value", "reaction"], required=("measure",))
    m = _measure(b, spec["measure"], f"{p}.measure", ctx)
    comps, units = _components(spec, m, p, ctx)
    value = None
    if "value" in spec:
        value = np.atleast_1d(ctx.vector(spec["value"], f"{p}.value"))
        if value.shape != (len(units),):
            raise ctx.error(f"{p}.value", f"expected {len(units)} values, got {value.size}")
        value = value * np.array([_unit_scale(u, ctx) for u in units])
    reaction = ctx.boolean(spec.get("reaction", True), f"{p}.reaction")  # `"false"` is text, not false
    _wrap(ctx, p, lambda: b.add_constraint(name, m, value, comps, reaction=reaction))


FUNCTION_KEYS = {
    "constant": ["value"],
    "polynomial": ["coefficients"],
    "fourier": ["frequency", "a", "b"],
    "spline": ["times", "values"],
    "gcv_spline": ["times", "values", "degree"],
}


def _function(spec, units, path, ctx):
    """Time function from its spec; values in the file's units of the driven measure."""
    ctx.mapping(spec, path)
    kind = spec.get("type")
    if not isinstance(kind, str) or kind not in FUNCTION_KEYS:
        raise ctx.error(f"{path}.type", f"unknown function type {kind!r}; expected one of {list(FUNCTION_KEYS)}")
    ctx.keys(spec, path, ["type"] + FUNCTION_KEYS[kind], required=["type"] + FUNCTION_KEYS[kind])
    scale = np.array([_unit_scale(u, ctx) for u in units])
    n = len(units)

    def rows(key):
        arr = ctx.vector(spec[key], f"{path}.{key}")
        if arr.ndim == 0:
            arr = arr.reshape(1, 1)
        elif arr.ndim == 1:
            arr = arr[:, None] if n == 1 else arr[None, :]
        if arr.shape[1] != n:
            raise ctx.error(f"{path}.{key}", f"each entry needs {n} values (one per driven component), got {arr.shape[1]}")
        return arr * scale

    try:
        if kind == "constant":
            return Constant(rows("value")[0])
        if kind == "polynomial":
            return Polynomial(rows("coefficients"))
        if kind == "fourier":
            return Fourier(ctx.number(spec["frequency"], f"{path}.frequency", positive=True), rows("a"), rows("b"))
        times = ctx.vector(spec["times"], f"{path}.times")
        if kind == "gcv_spline":
            degree = spec["degree"]
            if degree not in (1, 3, 5) or isinstance(degree, bool):
                raise ctx.error(f"{path}.degree", f"expected 1, 3 or 5, got {degree!r}")
            return SplineThroughData(times, rows("values"), natural=degree)
        return SplineThroughData(times, rows("values"))
    except ValueError as exc:
        if isinstance(exc, ModelError):
            raise
        raise ctx.error(path, str(exc)) from None


def _load_driver(b, name, spec, ctx):
    p = f"drivers.{name}"
    ctx.keys(spec, p, ["measure", "components", "function", "reaction"], required=("measure", "function"))
    m = _measure(b, spec["measure"], f"{p}.measure", ctx)
    comps, units = _components(spec, m, p, ctx)
    f = _function(spec["function"], units, f"{p}.function", ctx)
    reaction = ctx.boolean(spec.get("reaction", False), f"{p}.reaction")
    _wrap(ctx, p, lambda: b.add_driver(name, m, f, comps, reaction=reaction))


FDK_SETTING_KEYS = ["max_step", "perturbation"]


def _load_fdk(b, name, spec, ctx):
    p = f"fdk_dofs.{name}"
    ctx.keys(spec, p, ["measure", "component", "initial"] + FDK_SETTING_KEYS, required=("measure",))
    m = _measure(b, spec["measure"], f"{p}.measure", ctx)
    comp = spec.get("component")
    if comp is not None:
        comp = ctx.integer(comp, f"{p}.component", low=0, high=m.size - 1)
    elif m.size != 1:
        raise ctx.error(p, f"the measure has {m.size} components; give 'component' (0 to {m.size - 1})")
    unit = m.units[comp if comp is not None else 0]
    scale = _unit_scale(unit, ctx)
    initial = ctx.number(spec.get("initial", 0.0), f"{p}.initial") * scale
    settings = {k: spec[k] for k in FDK_SETTING_KEYS if k in spec}
    for k in ("max_step", "perturbation"):
        if k in settings:
            settings[k] = ctx.number(settings[k], f"{p}.{k}", positive=True) * scale
    _wrap(ctx, p, lambda: b.add_fdk_dof(name, m, initial, component=comp, **settings))
