"""Model-file sections of the force layer: muscles, ligaments, springs, reactions
(unilateral), loads and recruitment (format: docs/model-file.md, docs/muscles.md,
docs/ligaments.md). Read by :func:`openfdk.io.modelfile.model_from_dict`.

Units: lengths in the file's length unit, angles in its angle unit; forces N, moments
N m, stiffness N/m (ligaments, length springs) or N m/rad (angle springs) — always SI.
"""

from __future__ import annotations

import numpy as np

from ..model.model import ModelError
from ..model.modelfile import _function, _measure, _unit_scale, _wrap
from . import elements as el
from .hill import ConstantStrengthMuscle, Hill3ElementMuscle

HILL_LENGTH_KEYS = ("optimal_fibre_length", "tendon_slack_length")
HILL_KEYS = (
    "max_isometric_force", "tendon_strain_at_max_force", "pennation_angle_at_optimal",
    "fast_fibre_fraction", "passive_shape_factor", "passive_strain_at_max_force",
    "max_contraction_velocity", "force_length_width", "max_eccentric_force",
) + HILL_LENGTH_KEYS
#: model: millard (OpenSim's Millard2012EquilibriumMuscle; docs/muscles.md)
MILLARD_KEYS = (
    "max_isometric_force", "optimal_fibre_length", "tendon_slack_length", "pennation_angle_at_optimal",
    "max_contraction_velocity", "maximum_pennation_angle", "fiber_damping", "ignore_tendon_compliance",
    "minimum_activation", "active_force_length", "force_velocity", "fibre_force_length",
    "tendon_force_length", "curve_rule",
)
#: model: opensim_rigid_tendon / schutte1993 (OpenSim's RigidTendonMuscle and
#: Schutte1993Muscle_Deprecated, :mod:`.curve_muscle`); the curves are function dicts
CURVE_MUSCLE_MODELS = {"opensim_rigid_tendon": "rigid_tendon", "schutte1993": "schutte1993"}
CURVE_MUSCLE_KEYS = (
    "max_isometric_force", "optimal_fibre_length", "tendon_slack_length", "pennation_angle_at_optimal",
    "max_contraction_velocity", "time_scale", "damping", "active_force_length", "passive_force_length",
    "force_velocity", "tendon_force_length",
)
MILLARD_CURVE_KEYS = {
    "active_force_length": ("min_norm_active_fiber_length", "transition_norm_fiber_length",
                            "max_norm_active_fiber_length", "shallow_ascending_slope", "minimum_value"),
    "force_velocity": ("concentric_slope_at_vmax", "concentric_slope_near_vmax", "isometric_slope",
                       "eccentric_slope_at_vmax", "eccentric_slope_near_vmax",
                       "max_eccentric_velocity_force_multiplier", "concentric_curviness",
                       "eccentric_curviness"),
    "fibre_force_length": ("strain_at_zero_force", "strain_at_one_norm_force", "stiffness_at_low_force",
                           "stiffness_at_one_norm_force", "curviness"),
    "tendon_force_length": ("strain_at_one_norm_force", "stiffness_at_one_norm_force",
                            "norm_force_at_toe_end", "curviness"),
}


def _points(ctx, value, path, b=None):
    """A path: points 'body.point', wrapping-surface names (no dot), and conditional or
    moving points (mappings, :func:`_path_node`), ≥ 2 entries."""
    if not isinstance(value, list) or len(value) < 2 or not all(isinstance(p, (str, dict)) for p in value):
        raise ctx.error(path, f"expected a list of at least 2 points ('body.point') or wrapping surfaces, got {value!r}")
    if b is not None and any(isinstance(p, dict) for p in value):
        return [p if isinstance(p, str) else _path_node(b, ctx, p, f"{path}[{k}]") for k, p in enumerate(value)]
    if not all(isinstance(p, str) for p in value):
        raise ctx.error(path, "conditional and moving points are allowed in muscle and ligament paths only")
    return value


def _path_node(b, ctx, spec, path):
    """A conditional point ``{point, active: {coordinate, range}}`` or a moving point
    ``{frame, moving: {coordinate, x, y, z}}`` (each axis a function of the coordinate,
    in the file's units: x in the coordinate's unit, values in the length unit; or a
    number) -> the builder's mapping in SI (forces.elements.coordinate_path_measure)."""
    from ..model.coordinate_functions import function_from_spec
    from ..model.coordinates_section import _scaled, _scales

    units = {c.name: c.unit for c in b.elements.get("coordinates", ())}

    def coordinate(c, p):
        name = ctx.string(c, p)
        try:
            m = b.measure(name)
        except ModelError:
            raise ctx.error(p, f"unknown coordinate {name!r}") from None
        unit = units.get(name, m.units[0] if m.size == 1 else "")
        if unit not in ("angle", "length"):
            raise ctx.error(p, f"{name!r} is not a scalar angle or length coordinate")
        return name, _scales(ctx, unit)

    if "active" in spec:
        ctx.keys(spec, path, ["point", "active"], required=("point", "active"))
        act = ctx.keys(spec["active"], f"{path}.active", ["coordinate", "range"], required=("coordinate", "range"))
        name, scale = coordinate(act["coordinate"], f"{path}.active.coordinate")
        lo, hi = ctx.vector(act["range"], f"{path}.active.range", n=2) * scale
        if not lo <= hi:
            raise ctx.error(f"{path}.active.range", f"expected [low, high], got {act['range']!r}")
        return {"point": ctx.string(spec["point"], f"{path}.point"), "active": (name, float(lo), float(hi))}
    ctx.keys(spec, path, ["frame", "moving"], required=("frame", "moving"))
    mov = ctx.keys(spec["moving"], f"{path}.moving", ["coordinate", "x", "y", "z"], required=("coordinate",))
    name, scale = coordinate(mov["coordinate"], f"{path}.moving.coordinate")
    fns = []
    for axis in "xyz":
        f = mov.get(axis, 0.0)
        p = f"{path}.moving.{axis}"
        if isinstance(f, dict):
            fns.append(_scaled(function_from_spec(f, p, ctx.error), scale, ctx.length, p, ctx))
        else:
            fns.append(ctx.number(f, p) * ctx.length)
    return {"frame": ctx.string(spec["frame"], f"{path}.frame"), "moving": (name, tuple(fns))}


SIDES = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0), "+z": (0, 0, 1), "-z": (0, 0, -1)}


def load_wrapping(b, data, ctx):
    """``wrapping: {name: {type, frame, radius | semi_axes, tube_radius (torus), side, length (cylinder),
    crossing_only (sphere, ellipsoid), rule (ellipsoid), inside, one_segment}}`` (docs/muscles.md)."""
    for name, spec in ctx.mapping(data, "wrapping").items():
        p = f"wrapping.{name}"
        common = ["type", "frame", "side", "inside", "one_segment"]
        ctx.keys(spec, p, common + ["radius", "semi_axes", "length", "crossing_only", "tube_radius", "rule"],
                 required=("type", "frame"))
        kind = spec["type"]
        extra = {}
        if kind == "cylinder":
            ctx.keys(spec, p, common + ["radius", "length"], required=("radius",))
            dims = ctx.number(spec["radius"], f"{p}.radius", positive=True) * ctx.length
            if "length" in spec:
                extra["length"] = ctx.number(spec["length"], f"{p}.length", positive=True) * ctx.length
        elif kind == "sphere":
            ctx.keys(spec, p, common + ["radius", "crossing_only"], required=("radius",))
            dims = ctx.number(spec["radius"], f"{p}.radius", positive=True) * ctx.length
        elif kind == "ellipsoid":
            ctx.keys(spec, p, common + ["semi_axes", "crossing_only", "rule"], required=("semi_axes",))
            dims = ctx.vector(spec["semi_axes"], f"{p}.semi_axes", n=3) * ctx.length
            if "rule" in spec:
                if spec["rule"] not in ("shortest", "opensim"):
                    raise ctx.error(f"{p}.rule", f"expected 'shortest' or 'opensim', got {spec['rule']!r}")
                side = spec.get("side")
                if spec["rule"] == "opensim" and side is not None and not (isinstance(side, str) and side in SIDES):
                    raise ctx.error(f"{p}.side", f"with rule 'opensim' the side is a quadrant {list(SIDES)}, got "
                                                 f"{spec['side']!r}")
                extra["rule"] = spec["rule"]
        elif kind == "torus":
            ctx.keys(spec, p, ["type", "frame", "inside", "one_segment", "radius", "tube_radius"],
                     required=("radius", "tube_radius"))
            dims = np.array([ctx.number(spec[k], f"{p}.{k}", positive=True) for k in ("radius", "tube_radius")]) \
                * ctx.length
        else:
            raise ctx.error(f"{p}.type", f"unknown wrapping surface {kind!r}; expected cylinder, sphere, ellipsoid "
                                         "or torus")
        side = spec.get("side")
        if isinstance(side, str):
            if side not in SIDES:
                raise ctx.error(f"{p}.side", f"expected one of {list(SIDES)} or 3 numbers, got {side!r}")
            side = SIDES[side]
        elif side is not None:
            side = ctx.vector(side, f"{p}.side", n=3)
        for key in ("crossing_only", "one_segment"):
            if key in spec:
                if not isinstance(spec[key], bool):
                    raise ctx.error(f"{p}.{key}", f"expected true or false, got {spec[key]!r}")
                extra[key] = spec[key]
        if "inside" in spec:
            if spec["inside"] not in ("error", "straight"):
                raise ctx.error(f"{p}.inside", f"expected 'error' or 'straight', got {spec['inside']!r}")
            extra["inside"] = spec["inside"]
        if not isinstance(spec["frame"], str):
            raise ctx.error(f"{p}.frame", f"expected a frame name 'body.frame', got {spec['frame']!r}")
        _wrap(ctx, p, lambda: el.add_wrap_surface(b, name, kind, spec["frame"], dims, side, **extra))


def load_muscles(b, data, ctx):
    for name, spec in ctx.mapping(data, "muscles").items():
        p = f"muscles.{name}"
        ctx.keys(spec, p, ["path", "model", "strength", "min_control", "max_control",
                           *dict.fromkeys(HILL_KEYS + MILLARD_KEYS + CURVE_MUSCLE_KEYS)], required=("path",))
        kind = spec.get("model", "hill" if "max_isometric_force" in spec else "constant")
        points = _points(ctx, spec["path"], f"{p}.path", b)
        if kind in CURVE_MUSCLE_MODELS:
            law = _curve_muscle(name, spec, ctx, p, CURVE_MUSCLE_MODELS[kind])
        elif kind != "millard":
            for k in set(MILLARD_KEYS) - set(HILL_KEYS):
                if k in spec:
                    raise ctx.error(f"{p}.{k}", f"{k!r} belongs to 'model: millard'")
        if kind in CURVE_MUSCLE_MODELS:
            pass
        elif kind == "constant":
            if "strength" not in spec:
                raise ctx.error(p, "a constant-strength muscle needs 'strength' (N)")
            law = _wrap(ctx, p, lambda: ConstantStrengthMuscle(ctx.number(spec["strength"], f"{p}.strength", positive=True), name))
        elif kind == "hill":
            kw = {}
            for k in HILL_KEYS:
                if k in spec:
                    v = ctx.number(spec[k], f"{p}.{k}")
                    kw[k] = v * (ctx.length if k in HILL_LENGTH_KEYS else ctx.angle if k == "pennation_angle_at_optimal" else 1.0)
            for k in ("max_isometric_force", *HILL_LENGTH_KEYS):
                if k not in kw:
                    raise ctx.error(p, f"a Hill muscle needs {k!r}")
            law = _wrap(ctx, p, lambda: _hill(name, kw, ctx, p))
        elif kind == "millard":
            law = _millard(name, spec, ctx, p)
        else:
            raise ctx.error(f"{p}.model", f"unknown muscle model {kind!r}; expected 'constant', 'hill', 'millard', "
                                          "'opensim_rigid_tendon' or 'schutte1993'")
        controls = [ctx.number(spec.get(k, d), f"{p}.{k}", low=0.0, high=1.0)
                    for k, d in (("min_control", 0.0), ("max_control", 1.0))]
        _wrap(ctx, p, lambda: el.add_muscle(b, name, points, law, *controls))


def _curve_muscle(name, spec, ctx, p, kind):
    """A :class:`~.curve_muscle.CurveMuscle` from a ``model: opensim_rigid_tendon`` or
    ``schutte1993`` entry: lengths in the file's unit, the curves function dicts of the
    normalised variables (absent: OpenSim's defaults)."""
    from .curve_muscle import CurveMuscle

    for k in spec:
        if k not in CURVE_MUSCLE_KEYS and k not in ("path", "model", "min_control", "max_control"):
            raise ctx.error(f"{p}.{k}", f"{k!r} is not a key of 'model: {spec['model']}' (keys: "
                                        f"{list(CURVE_MUSCLE_KEYS)})")
    kw = {}
    for k in CURVE_MUSCLE_KEYS:
        if k not in spec:
            continue
        if k.endswith(("_length", "_velocity")) and isinstance(spec[k], dict):
            kw[k] = spec[k]
        else:
            scale = ctx.length if k in HILL_LENGTH_KEYS else ctx.angle if k == "pennation_angle_at_optimal" else 1.0
            kw[k] = ctx.number(spec[k], f"{p}.{k}") * scale
    for k in ("max_isometric_force", *HILL_LENGTH_KEYS):
        if k not in kw:
            raise ctx.error(p, f"a {spec['model']} muscle needs {k!r}")
    try:
        return CurveMuscle(kind=kind, name=name, **kw)
    except (ValueError, TypeError) as exc:
        raise ctx.error(p, str(exc)) from None


def _millard(name, spec, ctx, p):
    """A :class:`~.millard.MillardMuscle` from a ``model: millard`` entry."""
    from . import millard_curves as mc
    from .millard import MillardMuscle

    for k in set(HILL_KEYS) - set(MILLARD_KEYS):
        if k in spec:
            raise ctx.error(f"{p}.{k}", f"{k!r} is a Hill-model key; a Millard muscle takes {list(MILLARD_KEYS)}")
    kw = {}
    for k in MILLARD_KEYS:
        if k not in spec:
            continue
        if k in MILLARD_CURVE_KEYS:
            curve = ctx.keys(spec[k], f"{p}.{k}", list(MILLARD_CURVE_KEYS[k]))
            cls = {"active_force_length": mc.ActiveForceLengthCurve, "force_velocity": mc.ForceVelocityCurve,
                   "fibre_force_length": mc.FiberForceLengthCurve,
                   "tendon_force_length": mc.TendonForceLengthCurve}[k]
            kw[k] = _wrap(ctx, p, lambda: cls(**{c: ctx.number(v, f"{p}.{k}.{c}") for c, v in curve.items()}))
        elif k == "curve_rule":
            if spec[k] not in ("equilibrium", "as_given"):
                raise ctx.error(f"{p}.{k}", f"expected 'equilibrium' or 'as_given', got {spec[k]!r}")
            kw[k] = spec[k]
        elif k == "ignore_tendon_compliance":
            if not isinstance(spec[k], bool):
                raise ctx.error(f"{p}.{k}", f"expected true or false, got {spec[k]!r}")
            kw[k] = spec[k]
        else:
            scale = (ctx.length if k in HILL_LENGTH_KEYS else
                     ctx.angle if k in ("pennation_angle_at_optimal", "maximum_pennation_angle") else 1.0)
            kw[k] = ctx.number(spec[k], f"{p}.{k}") * scale
    for k in ("max_isometric_force", *HILL_LENGTH_KEYS):
        if k not in kw:
            raise ctx.error(p, f"a Millard muscle needs {k!r}")
    try:
        return MillardMuscle(name=name, **kw)
    except ValueError as exc:
        raise ctx.error(p, str(exc)) from None


def _hill(name, kw, ctx, path):
    try:
        return Hill3ElementMuscle(name=name, **kw)
    except ValueError as exc:
        raise ctx.error(path, str(exc)) from None


def load_ligaments(b, data, ctx):
    for name, spec in ctx.mapping(data, "ligaments").items():
        p = f"ligaments.{name}"
        ctx.keys(spec, p, ["path", "stiffness", "slack_length", "reference_length", "reference_strain",
                           "transition_strain", "damping", "damping_rule"], required=("path", "stiffness"))
        points = _points(ctx, spec["path"], f"{p}.path", b)
        k = ctx.number(spec["stiffness"], f"{p}.stiffness", positive=True)
        slack = ctx.number(spec["slack_length"], f"{p}.slack_length", positive=True) * ctx.length if "slack_length" in spec else None
        lref = spec.get("reference_length", "reference_pose")
        lref = None if lref == "reference_pose" else ctx.number(lref, f"{p}.reference_length", positive=True) * ctx.length
        eps_r = ctx.number(spec.get("reference_strain", 0.0), f"{p}.reference_strain")
        eps_l = ctx.number(spec.get("transition_strain", 0.03), f"{p}.transition_strain", positive=True)
        c = ctx.number(spec.get("damping", 0.0), f"{p}.damping", nonnegative=True)
        rule = ctx.choice(spec.get("damping_rule", "openfdk"), f"{p}.damping_rule", ("openfdk", "opensim"),
                          "damping rule")
        _wrap(ctx, p, lambda: el.add_ligament(b, name, points, k, slack, lref, eps_r, eps_l, c, rule))


LAW_KEYS = {"polynomial": ["coefficients"], "table": ["values", "forces"],
            "blankevoort": ["stiffness", "slack_length", "transition_strain"],
            "coordinate_limit": ["upper_limit", "upper_stiffness", "lower_limit", "lower_stiffness", "transition",
                                 "damping"],
            "expression": ["expression"]}
#: keys of a law that are optional
LAW_OPTIONAL = {"transition_strain", "damping"}


def load_springs(b, data, ctx):
    """Springs on scalar measures: linear (``stiffness``) or any ``law`` of
    :mod:`openfdk.forces.force_laws` (docs/ligaments.md, springs and force laws)."""
    from .force_laws import Blankevoort1991Spring, ForceLawError, PolynomialSpring, TabulatedSpring, add_nonlinear_spring

    for name, spec in ctx.mapping(data, "springs").items():
        p = f"springs.{name}"
        ctx.keys(spec, p, ["measure", "component", "stiffness", "rest_value", "law", "viscosity"], required=("measure",))
        m = _measure(b, spec["measure"], f"{p}.measure", ctx)
        if "component" in spec:
            m = _wrap(ctx, p, lambda: b._select(m, [spec["component"]]))
        unit = m.units[0]
        scale = _unit_scale(unit, ctx)
        si_unit = {"length": "m", "angle": "rad"}.get(unit, "1")
        rest = ctx.number(spec.get("rest_value", 0.0), f"{p}.rest_value") * scale
        if "law" not in spec:
            if "stiffness" not in spec:
                raise ctx.error(p, "missing required key 'stiffness' (or a 'law')")
            k = ctx.number(spec["stiffness"], f"{p}.stiffness", nonnegative=True)
            c = ctx.number(spec.get("viscosity", 0.0), f"{p}.viscosity", nonnegative=True)
            _wrap(ctx, p, lambda: el.add_spring(b, name, m, k, rest, si_unit, c))
            continue
        if "viscosity" in spec:
            raise ctx.error(f"{p}.viscosity", "a damper goes with a linear spring ('stiffness'), not a 'law'")
        if "stiffness" in spec:
            raise ctx.error(f"{p}.stiffness", "give either 'stiffness' (linear) or 'law', not both")
        law = ctx.mapping(spec["law"], f"{p}.law")
        kind = law.get("type")
        if kind not in LAW_KEYS:
            raise ctx.error(f"{p}.law.type", f"unknown force law {kind!r}; expected one of {list(LAW_KEYS)}")
        ctx.keys(law, f"{p}.law", ["type"] + LAW_KEYS[kind],
                 required=[k for k in LAW_KEYS[kind] if k not in LAW_OPTIONAL])
        try:
            if kind == "polynomial":
                fl = PolynomialSpring(ctx.vector(law["coefficients"], f"{p}.law.coefficients"), rest, si_unit, name)
            elif kind == "table":
                fl = TabulatedSpring(ctx.vector(law["values"], f"{p}.law.values") * scale,
                                     ctx.vector(law["forces"], f"{p}.law.forces"), si_unit, name)
            elif kind == "expression":  # f(q, qdot) in SI (OpenSim's ExpressionBasedCoordinateForce)
                from .expression_force import ExpressionLaw

                fl = ExpressionLaw(law["expression"], si_unit, name)
            elif kind == "coordinate_limit":  # limits and transition in the measure's unit, the rest SI
                from .limit_force import CoordinateLimitLaw

                num = {k: ctx.number(law.get(k, 0.0), f"{p}.law.{k}") for k in LAW_KEYS[kind]}
                fl = CoordinateLimitLaw(num["upper_limit"] * scale, num["upper_stiffness"], num["lower_limit"] * scale,
                                        num["lower_stiffness"], num["transition"] * scale, num["damping"], si_unit,
                                        name)
            else:
                if unit != "length":
                    raise ctx.error(f"{p}.law", "the blankevoort law needs a length measure")
                fl = Blankevoort1991Spring(ctx.number(law["stiffness"], f"{p}.law.stiffness", positive=True),
                                           ctx.number(law["slack_length"], f"{p}.law.slack_length", positive=True) * ctx.length,
                                           ctx.number(law.get("transition_strain", 0.03), f"{p}.law.transition_strain", positive=True),
                                           name)
        except ModelError:
            raise
        except (ForceLawError, ValueError) as exc:
            raise ctx.error(f"{p}.law", str(exc)) from None
        _wrap(ctx, p, lambda: add_nonlinear_spring(b, name, m, fl))


def load_bushings(b, data, ctx):
    """``bushings: {name: {parent, child, translational_stiffness: [3] N/m,
    rotational_stiffness: [3] N m/rad}}``."""
    from .force_laws import add_bushing

    for name, spec in ctx.mapping(data, "bushings").items():
        p = f"bushings.{name}"
        ctx.keys(spec, p, ["parent", "child", "translational_stiffness", "rotational_stiffness"],
                 required=("parent", "child", "translational_stiffness", "rotational_stiffness"))
        k_t = ctx.vector(spec["translational_stiffness"], f"{p}.translational_stiffness", n=3)
        k_r = ctx.vector(spec["rotational_stiffness"], f"{p}.rotational_stiffness", n=3)
        _wrap(ctx, p, lambda: add_bushing(b, name, spec["parent"], spec["child"], k_t, k_r))


def load_reactions(b, data, ctx):
    for name, spec in ctx.mapping(data, "reactions").items():
        p = f"reactions.{name}"
        ctx.keys(spec, p, ["joint", "row", "direction", "strength"], required=("joint",))
        row = spec.get("row", 0)
        if not isinstance(row, int) or isinstance(row, bool):
            raise ctx.error(f"{p}.row", f"expected a row index, got {row!r}")
        strength = ctx.number(spec.get("strength", 20e3), f"{p}.strength", positive=True)
        _wrap(ctx, p, lambda: el.add_unilateral_reaction(b, spec["joint"], row, spec.get("direction", "push"), strength, name))


def load_loads(b, data, ctx):
    for name, spec in ctx.mapping(data, "loads").items():
        p = f"loads.{name}"
        ctx.keys(spec, p, ["point", "force", "moment", "frame"], required=("point",))

        def vec(key):
            v = spec.get(key)
            if v is None:
                return None
            if isinstance(v, dict):  # a time function in SI units (N or N m)
                return _function(v, ("1", "1", "1"), f"{p}.{key}", ctx)
            return ctx.vector(v, f"{p}.{key}", n=3)

        _wrap(ctx, p, lambda: el.add_external_load(b, name, spec["point"], vec("force"), vec("moment"), spec.get("frame", "world")))


def load_recruitment(b, data, ctx):
    ctx.keys(data, "recruitment", ["criterion", "power", "tolerance", "static_optimization"])
    rule = ctx.choice(data.get("static_optimization", "openfdk"), "recruitment.static_optimization",
                      ("openfdk", "opensim"), "static_optimization")
    _wrap(ctx, "recruitment", lambda: el.set_recruitment(
        b, data.get("criterion", "polynomial"), ctx.number(data.get("power", 3.0), "recruitment.power"),
        ctx.number(data.get("tolerance", 1e-10), "recruitment.tolerance", positive=True), rule))
