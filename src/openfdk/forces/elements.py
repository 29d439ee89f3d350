"""Force elements attached to a model: muscles, ligaments, springs, unilateral reactions,
external loads, and the recruitment settings.

Elements are typed fields of the model (``model.muscles``, ``model.ligaments``,
``model.springs``, ``model.unilateral_reactions``, ``model.loads``; contacts in
:mod:`openfdk.contact.sections`) and are added with the functions here, which take a
:class:`~openfdk.model.builder.ModelBuilder`::

    add_muscle(b, "masseter_r", ["skull.mas_o_r", "mandible.mas_i_r"], Hill3ElementMuscle(...))
    add_ligament(b, "tmj_lig_r1", ["skull.tub_r", "mandible.neck_r1"],
                 stiffness=90.8, reference_strain=0.0)
    add_spring(b, "fdk_spring", b.measure("ml_shift"), stiffness=0.1)
    add_unilateral_reaction(b, "tmj_r", row=0, direction="push", strength=20e3)
    add_external_load(b, "bite", "mandible.incisor", force=Constant([0, 0, -50]))

Paths (sympy's pathway idea, STYLE.md §9): a muscle or ligament path is a chain of points
on bodies with straight segments between them; its length l is a measure (a sum of
distances), its lengthening speed is L v with L = ∂l/∂q̂, and a tension T ≥ 0 acts on the
bodies as the generalised force Q = −Lᵀ T (tension shortens the path).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.measures import Linear, Measure
from ..model.model import ModelError
from ..model.settings import checked_keywords
from ..model.timefunctions import Constant, TimeFunction
from .blankevoort import Blankevoort1991Ligament
from .spring import LinearSpring

MUSCLES, LIGAMENTS, SPRINGS, REACTIONS, LOADS, RECRUITMENT = (
    "muscles", "ligaments", "springs", "unilateral_reactions", "loads", "recruitment",
)


@dataclass(frozen=True, eq=False)
class Muscle:
    """A muscle: path measure (length, m) and a strength model (constant or Hill);
    min_control, max_control: its activation bounds in ``static_optimization: opensim``
    (OpenSim's, e.g. a Thelen2003Muscle's 0.01 and 1; openfdk's own rule uses [0, 1])."""

    name: str
    path: Measure
    law: object
    points: tuple = ()
    min_control: float = 0.0
    max_control: float = 1.0


@dataclass(frozen=True, eq=False)
class Ligament:
    """A ligament: path measure (m) and a Blankevoort1991Ligament law (passive load)."""

    name: str
    path: Measure
    law: Blankevoort1991Ligament
    points: tuple = ()


@dataclass(frozen=True, eq=False)
class Spring:
    """A spring on a scalar measure: generalised force f(m) − c ṁ along m (a linear law:
    f = −k (m − m_rest)); viscosity c ≥ 0 (N s/m or N m s/rad, OpenSim's
    SpringGeneralizedForce)."""

    name: str
    measure: Measure
    law: LinearSpring
    viscosity: float = 0.0


@dataclass(frozen=True, eq=False)
class UnilateralReaction:
    """Turns one joint reaction row into a bounded, one-sided actuator (recruited like a
    muscle, paper's 20 kN POP TMJ element): 0 ≤ f ≤ strength, acting along +Φ_q̂ᵀ of the
    row for ``direction = +1`` ("push": force on the child body toward increasing
    measure, e.g. along the plane normal of a point_on_plane joint) or −Φ_q̂ᵀ for −1."""

    name: str
    constraint: str
    row: int
    direction: int
    strength: float


@dataclass(frozen=True, eq=False)
class ExternalLoad:
    """A force (N) and moment (N m) on a body, as time functions of 3 components,
    applied at a point of the body; ``frame`` "world" or "body" for the components."""

    name: str
    body: int
    p_BP: np.ndarray
    force: TimeFunction
    moment: TimeFunction
    frame: str = "world"


@checked_keywords
@dataclass(frozen=True)
class RecruitmentSettings:
    """criterion: "polynomial" (power p ≥ 2; 3 as in the paper) or "minmax";
    static_optimization: "openfdk" (muscle strengths of :mod:`.hill`, passive forces
    applied, activations in [0, 1]) or "opensim" (OpenSim's StaticOptimization:
    :mod:`.rigid_tendon` strengths, no passive force, activations within each muscle's
    [min_control, max_control]). Exported as ``openfdk.RecruitmentSettings``; a misspelt
    keyword is refused naming it, with a did-you-mean."""

    criterion: str = "polynomial"
    power: float = 3.0
    tolerance: float = 1e-10
    static_optimization: str = "openfdk"


def path_measure(b, points, name=""):
    """Length (m) of the chain of points (qualified names, ≥ 2): Σ |p_{k+1} − p_k|.

    Names without a dot are wrapping surfaces added with :func:`add_wrap_surface`; a path
    with any of them is a :class:`~openfdk.forces.wrapping.WrappedPath` (first and last
    entries must be points). Mappings are conditional or moving points
    (:func:`coordinate_path_measure`)."""
    if len(points) < 2:
        raise ModelError(f"path {name!r}: needs at least 2 points, got {list(points)}")
    if any(isinstance(p, dict) for p in points):
        return coordinate_path_measure(b, points, name)
    if any(isinstance(p, str) and "." not in p for p in points):
        return wrapped_path_measure(b, points, name)
    terms = [(np.ones((1, 1)), b.distance(points[k], points[k + 1])) for k in range(len(points) - 1)]
    return Linear(terms, units=("length",), name=name)


def add_wrap_surface(b, name, kind, frame, dims, side=None, length=None, crossing_only=False, inside="error",
                     one_segment=False, rule="shortest"):
    """A wrapping surface named ``name`` fixed to the body of ``frame`` ("body.frame" or
    "body"; the surface axes are the frame's axes, a cylinder's axis is its z).

    kind : "cylinder" | "sphere" (dims = radius, m), "ellipsoid" (dims = 3 semi-axes,
    m) or "torus" (dims = (radius of the tube's centre circle, tube radius) m, axis z;
    OpenSim's WrapTorus: the path wraps the tube's inner side, :func:`~openfdk.forces.
    wrap_kernels.torus_wrap`); side : None or a direction (3,) in the surface frame on which paths must pass;
    length : a cylinder's length (m, centred on the frame; None: infinite), no wrap
    while both tangent points lie beyond its ends; crossing_only : a sphere or ellipsoid
    wraps only while the straight line crosses it (OpenSim's rule); inside : "error" (a
    path point inside the surface is an error naming the path) or "straight" (the path
    is straight there, OpenSim's rule); one_segment : a path that lists the surface in
    several segments wraps one of them (the first whose straight line crosses it, else
    the one that lengthens least: OpenSim's PathWrap over a range of points); rule :
    "shortest" or, for an ellipsoid, "opensim" (OpenSim's planar curve, ``side`` one of
    ±x, ±y, ±z as its quadrant or None: :mod:`~openfdk.forces.wrap_ellipsoid_plane`).
    Referenced by name in muscle and ligament paths (docs/muscles.md, wrapping)."""
    from ..model.names import check_name
    from .wrapping import SURFACE_KINDS, WrapSurface

    surfaces = b.__dict__.setdefault("wrap_surfaces", {})
    if not isinstance(name, str) or not name or "." in name:
        raise ModelError(f"wrapping surface name {name!r} must be a non-empty string without '.'")
    check_name(name, "wrapping surface")
    if name in surfaces:
        raise ModelError(f"wrapping surface {name!r} is defined twice")
    if kind not in SURFACE_KINDS:
        raise ModelError(f"wrapping surface {name!r}: type must be one of {sorted(SURFACE_KINDS)}, got {kind!r}")
    dims = np.atleast_1d(np.asarray(dims, dtype=float))
    if kind == "ellipsoid":
        if dims.shape != (3,):
            raise ModelError(f"wrapping surface {name!r}: an ellipsoid needs 3 semi-axes (m)")
    elif kind == "torus":
        if dims.shape != (2,) or not dims[0] > dims[1]:
            raise ModelError(f"wrapping surface {name!r}: a torus needs its radius and a smaller tube radius (m)")
        if side is not None or length is not None or crossing_only:
            raise ModelError(f"wrapping surface {name!r}: a torus takes no side, length or crossing_only")
        dims = np.array([dims[0], dims[1], dims[1]])
    else:
        if dims.shape != (1,):
            raise ModelError(f"wrapping surface {name!r}: a {kind} needs one radius (m)")
        dims = np.repeat(dims, 3)
    if not np.all(np.isfinite(dims) & (dims > 0)):
        raise ModelError(f"wrapping surface {name!r}: radius/semi-axes must be > 0 m, got {dims.tolist()}")
    side = np.zeros(3) if side is None else np.asarray(side, dtype=float)
    if side.shape != (3,) or not np.all(np.isfinite(side)):
        raise ModelError(f"wrapping surface {name!r}: side must be a direction of 3 numbers")
    if kind == "cylinder" and np.any(side) and not np.any(side[:2]):
        raise ModelError(f"wrapping surface {name!r}: a cylinder's side must not be along its axis (z)")
    half = np.inf
    if length is not None:
        if kind != "cylinder":
            raise ModelError(f"wrapping surface {name!r}: only a cylinder has a length")
        if not (np.isfinite(length) and length > 0):
            raise ModelError(f"wrapping surface {name!r}: length must be > 0 m, got {length!r}")
        half = 0.5 * float(length)
    if crossing_only and kind == "cylinder":
        raise ModelError(f"wrapping surface {name!r}: crossing_only is for spheres and ellipsoids")
    if inside not in ("error", "straight"):
        raise ModelError(f"wrapping surface {name!r}: inside must be 'error' or 'straight', got {inside!r}")
    if rule not in ("shortest", "opensim"):
        raise ModelError(f"wrapping surface {name!r}: rule must be 'shortest' or 'opensim', got {rule!r}")
    if rule == "opensim":
        if kind != "ellipsoid":
            raise ModelError(f"wrapping surface {name!r}: rule 'opensim' is for ellipsoids")
        if np.count_nonzero(side) > 1:
            raise ModelError(f"wrapping surface {name!r}: with rule 'opensim' the side is a quadrant: +x, -x, +y, "
                             "-y, +z or -z")
        side = np.sign(side)
    f = b.frame(frame if "." in frame else f"{frame}.origin")
    surface = WrapSurface(name, kind, b._body_index(f.body), np.asarray(f.p_BF, dtype=float),
                          np.asarray(f.R_BF, dtype=float), dims, side, half, bool(crossing_only),
                          inside == "straight", bool(one_segment), rule == "opensim")
    surfaces[name] = surface
    return surface


def wrapped_path_measure(b, entries, name=""):
    """A :class:`~openfdk.forces.wrapping.WrappedPath` through points ("body.point") and
    wrapping surfaces (names) in any order; first and last entries must be points."""
    from .wrapping import WrappedPath

    surfaces = b.__dict__.get("wrap_surfaces", {})
    nodes = []
    for k, entry in enumerate(entries):
        if isinstance(entry, str) and "." not in entry:
            if entry not in surfaces:
                raise ModelError(f"path {name!r}: unknown wrapping surface {entry!r}; known: {sorted(surfaces)}")
            if k in (0, len(entries) - 1):
                raise ModelError(f"path {name!r}: must start and end at a point, not at surface {entry!r}")
            nodes.append(surfaces[entry])
        else:
            f = b.frame(entry)
            nodes.append((b._body_index(f.body), np.asarray(f.p_BF, dtype=float)))
    return WrappedPath(nodes, name)


def coordinate_path_measure(b, entries, name=""):
    """A :class:`~openfdk.forces.coordinate_path.CoordinatePath` through fixed points
    ("body.point") and mappings, in SI units:

    * ``{"point": "body.point", "active": (coordinate, lo, hi)}`` — in the path while
      lo ≤ coordinate ≤ hi (rad or m);
    * ``{"frame": "body.frame", "moving": (coordinate, (f_x, f_y, f_z))}`` — at
      (f_x(u), f_y(u), f_z(u)) m in the frame's axes, each f a PiecewisePolynomial of the
      coordinate u (its value clamped to the coordinate's range) or a float (m).

    ``coordinate`` names a scalar measure (a joint coordinate). Names without a dot are
    wrapping surfaces (:func:`add_wrap_surface`): the path is then a
    :class:`~openfdk.forces.coordinate_wrapping.CoordinateWrappedPath` (first and last
    entries fixed or moving points)."""
    from .coordinate_path import CoordinatePath, PathNode

    ranges = {c.name: c.range for c in b.elements.get("coordinates", ())}

    def coordinate(cname, what):
        m = b.measure(cname)
        if m.size != 1:
            raise ModelError(f"path {name!r}: {what} coordinate {cname!r} has {m.size} rows; expected a scalar")
        return m

    surfaces = b.__dict__.get("wrap_surfaces", {})
    nodes = []
    for k, entry in enumerate(entries):
        if isinstance(entry, str):
            if "." not in entry:
                if entry not in surfaces:
                    raise ModelError(f"path {name!r}: unknown wrapping surface {entry!r}; known: {sorted(surfaces)}")
                if k in (0, len(entries) - 1):
                    raise ModelError(f"path {name!r}: must start and end at a point, not at surface {entry!r}")
                nodes.append(surfaces[entry])
                continue
            f = b.frame(entry)
            nodes.append(PathNode(b._body_index(f.body), np.asarray(f.p_BF, float), np.eye(3)))
        elif "active" in entry:
            cname, lo, hi = entry["active"]
            if not lo <= hi:
                raise ModelError(f"path {name!r}: range [{lo:g}, {hi:g}] of {entry.get('point')!r} is empty")
            f = b.frame(entry["point"])
            nodes.append(PathNode(b._body_index(f.body), np.asarray(f.p_BF, float), np.eye(3),
                                  condition=(coordinate(cname, "conditional point"), float(lo), float(hi))))
        else:
            cname, fns = entry["moving"]
            f = b.frame(entry["frame"])
            lo, hi = ranges.get(cname, (-np.inf, np.inf))
            nodes.append(PathNode(b._body_index(f.body), np.asarray(f.p_BF, float), np.asarray(f.R_BF, float),
                                  moving=(coordinate(cname, "moving point"), float(lo), float(hi), tuple(fns))))
    if any(not isinstance(n, PathNode) for n in nodes):
        from .coordinate_wrapping import CoordinateWrappedPath

        for end in (entries[0], entries[-1]):
            if isinstance(end, dict) and "active" in end:
                raise ModelError(f"path {name!r}: a wrapped path cannot start or end at a conditional point "
                                 f"({end['point']!r})")
        return CoordinateWrappedPath(nodes, name)
    return CoordinatePath(nodes, name)


def _append(b, kind, element):
    from ..model.names import check_name

    check_name(element.name, "force element")
    items = list(b.elements.get(kind, ()))
    all_names = {e.name for k in (MUSCLES, LIGAMENTS, SPRINGS, REACTIONS, LOADS) for e in b.elements.get(k, ())}
    if element.name in all_names:
        raise ModelError(f"force element {element.name!r} is defined twice")
    items.append(element)
    b.elements[kind] = tuple(items)
    return element


def add_muscle(b, name, points, law, min_control=0.0, max_control=1.0):
    """A muscle along ``points`` with a strength model from :mod:`openfdk.forces.hill`;
    min_control < max_control in [0, 1]: its activation bounds in OpenSim's static
    optimisation (``static_optimization: opensim``)."""
    if not (0.0 <= min_control < max_control <= 1.0):
        raise ModelError(f"muscle {name!r}: need 0 <= min_control < max_control <= 1, got [{min_control}, "
                         f"{max_control}]")
    return _append(b, MUSCLES, Muscle(name, path_measure(b, points, name), law, tuple(points), float(min_control),
                                      float(max_control)))


def reference_length(b, measure):
    """Value of a scalar measure in the builder's reference pose (bodies' initial poses)."""
    from ..model.state import BodyStates

    names = [r["name"] for r in b._bodies]
    state = BodyStates([r["position"] for r in b._bodies], [r["quat"] for r in b._bodies], [-1] * len(names))
    return float(measure.evaluate(state, 0)[0][0])


def add_ligament(b, name, points, stiffness, slack_length=None, reference_length_m=None,
                 reference_strain=0.0, transition_strain=0.03, damping=0.0, damping_rule="openfdk"):
    """A Blankevoort ligament along ``points``. Slack length given directly (m), or from
    a reference length l_r (m; default: the path length in the reference pose) and a
    reference strain ε_r: l0 = l_r / (1 + ε_r). stiffness k in N/m; damping c in N·s/m
    with its rule (:class:`~.blankevoort.Blankevoort1991Ligament`)."""
    path = path_measure(b, points, name)
    if slack_length is not None:
        law = Blankevoort1991Ligament(stiffness, slack_length, transition_strain, damping, name=name,
                                      damping_rule=damping_rule)
    else:
        l_r = reference_length(b, path) if reference_length_m is None else reference_length_m
        law = Blankevoort1991Ligament.from_reference(stiffness, l_r, reference_strain, transition_strain, damping,
                                                     name=name)
        if damping_rule != "openfdk":
            from dataclasses import replace

            law = replace(law, damping_rule=damping_rule)
    return _append(b, LIGAMENTS, Ligament(name, path, law, tuple(points)))


def add_spring(b, name, measure, stiffness, rest_value=0.0, unit="m", viscosity=0.0):
    """A linear spring on a scalar measure (k in N/m or N m/rad), with a damper of
    viscosity c ≥ 0 (N s/m or N m s/rad) in parallel."""
    if isinstance(measure, str):
        measure = b.measure(measure)
    if measure.size != 1:
        raise ModelError(f"spring {name!r}: the measure must be scalar")
    if not (np.isfinite(viscosity) and viscosity >= 0.0):
        raise ModelError(f"spring {name!r}: viscosity must be a finite number >= 0, got {viscosity!r}")
    return _append(b, SPRINGS, Spring(name, measure, LinearSpring(stiffness, rest_value, unit, name=name),
                                      float(viscosity)))


def add_unilateral_reaction(b, constraint, row=0, direction="push", strength=20e3, name=None):
    """Make row ``row`` of joint ``constraint`` a one-sided bounded reaction."""
    names = [c.name for c in b._constraints]
    if constraint not in names:
        raise ModelError(f"unilateral reaction: unknown joint/constraint {constraint!r}; known: {names}")
    c = b._constraints[names.index(constraint)]
    if not (0 <= row < c.size):
        raise ModelError(f"unilateral reaction on {constraint!r}: row {row} out of range (0..{c.size - 1})")
    if not c.reaction:
        raise ModelError(f"unilateral reaction on {constraint!r}: this constraint carries no reaction")
    sign = {"push": 1, "pull": -1}.get(direction)
    if sign is None:
        raise ModelError(f"unilateral reaction on {constraint!r}: direction must be 'push' or 'pull', got {direction!r}")
    if not (np.isfinite(strength) and strength > 0):
        raise ModelError(f"unilateral reaction on {constraint!r}: strength must be > 0 N")
    el = UnilateralReaction(name or c.row_names[row], constraint, int(row), sign, float(strength))
    for other in b.elements.get(REACTIONS, ()):
        if other.constraint == constraint and other.row == row:
            raise ModelError(f"row {row} of {constraint!r} is made unilateral twice")
    return _append(b, REACTIONS, el)


def add_external_load(b, name, point, force=None, moment=None, frame="world"):
    """External force (N) and moment (N m) at ``point`` ("body.frame"): time functions
    of 3 components or constant triples."""
    f = b.frame(point)
    body = b._body_index(f.body)
    force = Constant(np.zeros(3) if force is None else force) if not isinstance(force, TimeFunction) else force
    moment = Constant(np.zeros(3) if moment is None else moment) if not isinstance(moment, TimeFunction) else moment
    if force.size != 3 or moment.size != 3:
        raise ModelError(f"load {name!r}: force and moment need 3 components")
    if frame not in ("world", "body"):
        raise ModelError(f"load {name!r}: frame must be 'world' or 'body', got {frame!r}")
    return _append(b, LOADS, ExternalLoad(name, body, f.p_BF, force, moment, frame))


def set_recruitment(b, criterion="polynomial", power=3.0, tolerance=1e-10, static_optimization="openfdk"):
    if criterion not in ("polynomial", "minmax"):
        raise ModelError(f"recruitment criterion must be 'polynomial' or 'minmax', got {criterion!r}")
    if criterion == "polynomial" and not (np.isfinite(power) and power >= 2):
        raise ModelError(f"recruitment power must be >= 2, got {power}")
    if static_optimization not in ("openfdk", "opensim"):
        raise ModelError(f"recruitment static_optimization must be 'openfdk' or 'opensim', got {static_optimization!r}")
    if static_optimization == "opensim" and criterion != "polynomial":
        raise ModelError("static_optimization: opensim needs the polynomial criterion (OpenSim's Σ aᵖ)")
    b.elements[RECRUITMENT] = RecruitmentSettings(criterion, float(power), float(tolerance), static_optimization)


__all__ = [
    "Muscle", "Ligament", "Spring", "UnilateralReaction", "ExternalLoad", "RecruitmentSettings",
    "add_muscle", "add_ligament", "add_spring", "add_unilateral_reaction", "add_external_load",
    "set_recruitment", "path_measure", "add_wrap_surface", "wrapped_path_measure", "coordinate_path_measure",
]
