"""Model-file sections of OpenSim-style joints: ``coordinates``, joints of type
``custom`` and ``couplers`` (docs/model-file.md, "Joint coordinates"; what they mean:
:mod:`openfdk.model.coordinate_joint`).

::

    coordinates:
      knee_angle_r: {motion: rotational, default: 0, range: [-120, 10], clamped: true}
    joints:
      knee_r:
        type: custom
        parent: femur_r.knee_r_in_parent
        child: tibia_r.knee_r_in_child
        rotations:                       # OpenSim's rotation1-3 (intrinsic sequence)
          - {axis: [0, 0, 1], coordinate: knee_angle_r}          # linear, slope 1
          - {axis: [1, 0, 0], value: 0}                           # constant
          - {axis: [0, 1, 0], value: 0}
        translations:                    # OpenSim's translation1-3 (in the parent frame)
          - {axis: [1, 0, 0], coordinate: knee_angle_r,
             function: {type: simm_spline, x: [-120, 0, 10], y: [-0.003, 0, 0.001]}}
          - {axis: [0, 1, 0], value: 0}
          - {axis: [0, 0, 1], value: 0}
    couplers:
      patella: {independent: knee_angle_r, dependent: patella_angle, function: {type: linear, slope: 1, intercept: 0}}

A coordinate that no axis of its joint moves linearly (only through splines) is the
function of its coupler's independent coordinate (OpenSim's Rajagopal 2016 patella:
``knee_angle_r_beta`` follows ``knee_angle_r``); that coupler then adds no row. Joints
are loaded in file order, a joint waiting for another's coordinate after it.

Units: a coordinate's values are in the file's angle unit (rotational, coupled) or
length unit (translational); a function's x in its coordinate's unit and y in the axis'
unit (angle for rotations, length for translations); ``value`` likewise.
"""

from __future__ import annotations

import numpy as np

from .coordinate_functions import function_from_spec
from .coordinate_joint import (COORDINATE_UNITS, Axis, Coordinate, CoordinateTimeFunction, add_coordinate_joint,
                               add_coupler, affine)
from .function_measure import FunctionOf

COORDINATE_KEYS = ["motion", "default", "range", "clamped", "locked", "prescribed", "opensim_motion"]
AXIS_KEYS = ["axis", "coordinate", "function", "value"]


def read_coordinates(spec, ctx):
    """The ``coordinates`` section -> {name: dict(motion, unit, default, range, clamped,
    locked, prescribed)} in SI (not yet measures: the joints define those)."""
    out = {}
    for name, c in ctx.mapping(spec or {}, "coordinates").items():
        p = f"coordinates.{name}"
        c = ctx.keys(c or {}, p, COORDINATE_KEYS)
        motion = ctx.choice(c.get("motion", "rotational"), f"{p}.motion", COORDINATE_UNITS, "motion type")
        # OpenSim's motion type when it differs (an .osim's coupled coordinate): which
        # .mot columns OpenSim writes and reads in degrees (only its rotational ones)
        opensim_motion = ctx.choice(c.get("opensim_motion", motion), f"{p}.opensim_motion", COORDINATE_UNITS,
                                    "motion type")
        unit = COORDINATE_UNITS[motion]
        scale = ctx.angle if unit == "angle" else ctx.length
        rng = (-np.inf, np.inf)
        if "range" in c:
            rng = tuple(ctx.vector(c["range"], f"{p}.range", n=2) * scale)
            if rng[0] > rng[1]:
                raise ctx.error(f"{p}.range", f"lower bound above the upper: {c['range']!r}")
        out[name] = dict(motion=motion, unit=unit, default=ctx.number(c.get("default", 0.0), f"{p}.default") * scale,
                         range=rng, clamped=ctx.boolean(c.get("clamped", False), f"{p}.clamped"),
                         locked=ctx.boolean(c.get("locked", False), f"{p}.locked"), prescribed=None,
                         opensim_motion=opensim_motion)
        if c.get("prescribed") is not None:
            fn = function_from_spec(c["prescribed"], f"{p}.prescribed", ctx.error)
            out[name]["prescribed"] = _scaled(fn, 1.0, scale, f"{p}.prescribed", ctx)
    return out


def _missing_axis(given, k):
    """The axis (3,) of a joint's k-th rotation or translation that the file leaves out (a
    constant 0: it moves nothing): the unit axis e_k, unless that lies in the span of the
    axes before it (a single rotation about z would leave y, z), then the first unit axis
    that does not, so that the three axes are independent, as OpenSim requires of a
    CustomJoint's (the joint exported by ``openfdk export-opensim`` loads there)."""
    E = np.eye(3)
    basis = np.zeros((3, 0))
    for a in given:
        r = a - basis @ (basis.T @ a)
        if np.linalg.norm(r) > 1e-9:
            basis = np.column_stack([basis, r / np.linalg.norm(r)])
    for e in [E[k]] + [E[i] for i in range(3) if i != k]:
        if np.linalg.norm(e - basis @ (basis.T @ e)) > 0.5:
            return e
    return E[k]


def _scales(ctx, unit):
    return ctx.angle if unit == "angle" else ctx.length


def _scaled(fn, sx, sy, path, ctx):
    """``fn.scaled(sx, sy)``, or the file's error when the unit change overflows."""
    try:
        return fn.scaled(sx, sy)
    except ValueError as exc:
        raise ctx.error(path, f"{exc} in SI units (the numbers are too large)") from None


def _coupler_function(cname, cspec, coordinates, ctx):
    """The PiecewisePolynomial (SI) of the coupler ``cname`` (its spec ``cspec``), its
    coordinates checked."""
    p = f"couplers.{cname}"
    ctx.keys(cspec, p, ["independent", "dependent", "function"], required=("independent", "dependent", "function"))
    for key in ("independent", "dependent"):
        if not isinstance(cspec[key], str) or cspec[key] not in coordinates:
            raise ctx.error(f"{p}.{key}", f"unknown coordinate {cspec[key]!r}; declare it under coordinates:")
    if cspec["independent"] == cspec["dependent"]:
        raise ctx.error(f"{p}.dependent", f"{cspec['dependent']!r} is also the independent coordinate; a coupler "
                                          "relates two coordinates")
    fn = function_from_spec(cspec["function"], f"{p}.function", ctx.error)
    return _scaled(fn, _scales(ctx, coordinates[cspec["independent"]]["unit"]),
                   _scales(ctx, coordinates[cspec["dependent"]]["unit"]), f"{p}.function", ctx)


def load_custom_joint(b, name, spec, coordinates, ctx, wrap, couplers=None, last_try=True):
    """A joint of type ``custom`` (module docstring); defines its coordinates' measures.

    A coordinate that no axis of the joint moves linearly is, when a coupler of
    ``couplers`` (the model file's section) has it as its dependent, that coupler's
    function of its independent coordinate (:func:`~openfdk.model.coordinate_joint.add_coordinate_joint`).
    If that independent coordinate's joint is not loaded yet, nothing is added and
    False is returned (unless ``last_try``: then the coupler is named in an error);
    else True."""
    p = f"joints.{name}"
    ctx.keys(spec, p, ["type", "parent", "child", "rotations", "translations"], required=("type", "parent", "child"))
    axes = {}
    mine = {}
    for kind in ("rotations", "translations"):
        items = spec.get(kind) or []
        if not isinstance(items, list) or len(items) > 3:
            raise ctx.error(f"{p}.{kind}", "expected a list of at most 3 axes")
        out = []
        for k in range(3):
            ap = f"{p}.{kind}[{k}]"
            a = ctx.keys(items[k], ap, AXIS_KEYS) if k < len(items) else \
                {"axis": _missing_axis([ax.axis for ax in out], k).tolist(), "value": 0.0}
            defaults = np.eye(3)
            axis = ctx.vector(a.get("axis", defaults[k].tolist()), f"{ap}.axis", n=3)
            norm = float(np.linalg.norm(axis))
            if not np.isfinite(norm):  # components near the float limit: scale down first
                axis = axis / np.max(np.abs(axis))
                norm = float(np.linalg.norm(axis))
            axis_unit = "angle" if kind == "rotations" else "length"
            label = f"{kind[:-1]}{k + 1}"
            coord = a.get("coordinate")
            if coord is None:
                if "function" in a:
                    raise ctx.error(ap, "a function needs a 'coordinate'")
                value = ctx.number(a.get("value", 0.0), f"{ap}.value") * _scales(ctx, axis_unit)
                if norm == 0.0 and value != 0.0:
                    raise ctx.error(f"{ap}.axis", "a zero axis")
                out.append(Axis(label, axis / (norm or 1.0), None, value))
                continue
            if "value" in a:
                raise ctx.error(ap, "give either 'value' (a constant axis) or 'coordinate' (and 'function')")
            if not isinstance(coord, str) or coord not in coordinates:
                raise ctx.error(f"{ap}.coordinate", f"unknown coordinate {coord!r}; declare it under coordinates:")
            if norm == 0.0:
                raise ctx.error(f"{ap}.axis", "a zero axis")
            cunit = coordinates[coord]["unit"]
            fspec = a.get("function", {"type": "linear", "slope": 1.0, "intercept": 0.0})
            fn = function_from_spec(fspec, f"{ap}.function", ctx.error)
            fn = _scaled(fn, _scales(ctx, cunit), _scales(ctx, axis_unit), f"{ap}.function", ctx)
            out.append(Axis(label, axis / norm, coord, fn))
            mine[coord] = cunit
        axes[kind] = out
    linear = {ax.coordinate for kind in axes.values() for ax in kind
              if ax.coordinate is not None and (line := affine(ax.function)) is not None and line[0] != 0.0}
    by_dependent = {c["dependent"]: (n, c) for n, c in ctx.mapping(couplers or {}, "couplers").items()
                    if isinstance(c, dict) and isinstance(c.get("dependent"), str)}
    coupled, coupled_by = {}, {}
    for cname in mine:
        if cname in linear or cname not in by_dependent:
            continue
        cp_name, cspec = by_dependent[cname]
        fn = _coupler_function(cp_name, cspec, coordinates, ctx)
        independent = coordinates[cspec["independent"]]
        if "measure" not in independent:
            if not last_try:
                return False
            raise ctx.error(f"couplers.{cp_name}.independent", f"coordinate {cspec['independent']!r} is moved by no "
                                                                f"joint, so {cname!r} (joint {name!r}) cannot follow it")
        coupled[cname] = FunctionOf(fn, independent["measure"], coordinates[cname]["unit"], name=cname)
        coupled_by[cname] = cp_name
    defined = wrap(ctx, p, lambda: add_coordinate_joint(b, name, spec["parent"], spec["child"], axes["rotations"],
                                                        axes["translations"], mine, coupled=coupled))
    for cname, measure in defined.items():
        c = coordinates[cname]
        if c.get("joint"):
            raise ctx.error(p, f"coordinate {cname!r} is already moved by joint {c['joint']!r}")
        c["joint"], c["measure"] = name, measure
        if cname in coupled_by:
            c["coupled_by"] = coupled_by[cname]
    return True


def finish_coordinates(b, coordinates, ctx, wrap):
    """After the joints: every declared coordinate has a joint; locked ones get a row
    ``{name}.locked``, prescribed ones a driver ``{name}.prescribed``; the Coordinate
    records go to ``model.coordinates``."""
    records = []
    for name, c in coordinates.items():
        p = f"coordinates.{name}"
        if "measure" not in c:
            raise ctx.error(p, "no joint of type custom moves this coordinate")
        if c["locked"] and c["prescribed"] is not None:
            raise ctx.error(p, "a coordinate cannot be both locked and prescribed")
        if c["locked"]:
            wrap(ctx, p, lambda: b.add_constraint(f"{name}_locked", c["measure"], [c["default"]]))
        if c["prescribed"] is not None:
            wrap(ctx, p, lambda: b.add_driver(f"{name}_prescribed", c["measure"],
                                              CoordinateTimeFunction(c["prescribed"]), reaction=True))
        records.append(Coordinate(name, c["joint"], c["motion"], c["unit"], c["measure"], c["default"], c["range"],
                                  c["clamped"], c["locked"], c["prescribed"] is not None,
                                  c.get("opensim_motion") or c["motion"]))
    b.elements["coordinates"] = records


def load_couplers(b, spec, coordinates, ctx, wrap):
    """The ``couplers`` section: {name: {independent, dependent, function}}."""
    for name, c in ctx.mapping(spec or {}, "couplers").items():
        p = f"couplers.{name}"
        fn = _coupler_function(name, c, coordinates, ctx)
        held = coordinates[c["dependent"]].get("coupled_by") == name  # the joint placed it by this coupler
        wrap(ctx, p, lambda: add_coupler(b, name, c["independent"], c["dependent"], fn, by_construction=held))
