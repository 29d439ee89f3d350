"""Python builder API: the same models as the YAML model files, built in code.

Example (a pendulum)::

    b = ModelBuilder("pendulum")
    b.add_body("bob", mass=1.0, inertia=[1e-3, 1e-3, 1e-3], position=[0, 0, -0.5])
    b.add_frame("bob", "pivot", [0, 0, 0.5])
    b.add_joint("pin", "revolute", parent="ground.origin", child="bob.pivot")
    b.add_driver("swing", b.angles("ground.origin", "bob.origin"), Polynomial([0, 1.0]),
                 components=[2])
    model = b.build()

All lengths in m, angles in rad (the model-file loader converts file units first).
"""

from __future__ import annotations

import numpy as np

from ..spatial import normalize_quat, quat_from_matrix
from .components import GROUND, Body, Frame, Marker
from .constraints import DRIVER, JOINT, Constraint, FDKDof, MarkerSet
from .measures import AxisDot, Distance, Linear, Measure, PointPosition, RelativeAngles, RelativeVector
from .model import Model, ModelError
from .timefunctions import Constant, TimeFunction

JOINT_TYPES = ("weld", "spherical", "revolute", "prismatic", "point_on_plane", "generic")

_EX, _EY, _EZ = np.eye(3)


def _check_name(name, what):
    if not isinstance(name, str) or not name or "." in name or name.strip() != name:
        raise ModelError(f"{what} name {name!r} must be a non-empty string without '.' or spaces")


def _orientation(value, what):
    """Accept a quaternion (4,), a rotation matrix (3, 3) or None -> unit quaternion."""
    if value is None:
        return np.array([1.0, 0.0, 0.0, 0.0])
    arr = np.asarray(value, dtype=float)
    if arr.shape == (4,):
        return normalize_quat(arr)
    if arr.shape == (3, 3):
        if not np.allclose(arr @ arr.T, np.eye(3), atol=1e-6) or np.linalg.det(arr) < 0:
            raise ModelError(f"{what}: orientation matrix is not a rotation")
        return quat_from_matrix(arr)
    raise ModelError(f"{what}: orientation must be a quaternion (4,) or matrix (3, 3)")


class ModelBuilder:
    """Collects bodies, frames, markers, measures, constraints and FDK DOFs, then
    validates them once in :meth:`build`. Methods raise :class:`ModelError` naming the
    offending entry as soon as something is wrong."""

    def __init__(self, name="model", gravity=(0.0, 0.0, -9.81)):
        self.name = name
        self.gravity_W = np.asarray(gravity, dtype=float)
        if self.gravity_W.shape != (3,):
            raise ModelError(f"gravity must have 3 components, got {gravity!r}")
        self._bodies = []
        self._frames = {}
        self._markers = []
        self._measures = {}
        self._constraints = []
        self._fdk = []
        self.elements = {}
        self.source = ""
        self._add_body_record(GROUND, 0.0, np.zeros((3, 3)), np.zeros(3), None, fixed=True, equilibrium=False)

    # -- bodies and frames -----------------------------------------------------------
    def _body_index(self, name, what="body"):
        for i, b in enumerate(self._bodies):
            if b["name"] == name:
                return i
        known = [b["name"] for b in self._bodies]
        raise ModelError(f"{what}: unknown body {name!r}; known bodies: {known}")

    def _add_body_record(self, name, mass, inertia, position, orientation, fixed, equilibrium):
        self._bodies.append(
            dict(
                name=name, mass=mass, inertia=inertia, position=position,
                quat=_orientation(orientation, f"body {name!r}"), fixed=fixed, equilibrium=equilibrium,
            )
        )
        self._frames[f"{name}.origin"] = Frame(f"{name}.origin", name, np.zeros(3), np.eye(3))

    def add_body(self, name, mass, inertia, position=(0, 0, 0), orientation=None, fixed=False, equilibrium=True):
        """Add a rigid body.

        mass : kg (> 0 for a moving body); inertia : (3,) principal moments or (3, 3)
        kg m² about the centre of mass in the body frame; position : (3,) m of the
        centre of mass (the body frame origin) in the reference pose; orientation :
        quaternion (4,) or rotation matrix R_WB (3, 3); fixed : fixed to the world.
        """
        _check_name(name, "body")
        if any(b["name"] == name for b in self._bodies):
            raise ModelError(f"body {name!r} is defined twice")
        inertia = np.asarray(inertia, dtype=float)
        if inertia.shape == (3,):
            inertia = np.diag(inertia)
        if inertia.shape != (3, 3):
            raise ModelError(f"body {name!r}: inertia must be 3 principal moments or a 3x3 matrix")
        if not fixed:
            if not (np.isfinite(mass) and mass > 0):
                raise ModelError(f"body {name!r}: mass must be > 0 kg, got {mass}")
            if not np.allclose(inertia, inertia.T) or np.any(np.linalg.eigvalsh(inertia) <= 0):
                raise ModelError(f"body {name!r}: inertia must be symmetric positive definite")
        position = np.asarray(position, dtype=float)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ModelError(f"body {name!r}: position must be 3 finite numbers")
        self._add_body_record(name, float(mass), inertia, position, orientation, bool(fixed), bool(equilibrium))
        return name

    def add_frame(self, body, name, position, orientation=None):
        """A frame (or point, with ``orientation=None``) fixed on ``body``.

        position : (3,) m in the body frame; orientation : R_BF (3, 3) or quaternion.
        Returns its qualified name "body.name".
        """
        self._body_index(body, f"frame {name!r}")
        _check_name(name, "frame/point")
        qualified = f"{body}.{name}"
        if qualified in self._frames:
            raise ModelError(f"frame/point {qualified!r} is defined twice")
        p = np.asarray(position, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ModelError(f"frame/point {qualified!r}: position must be 3 finite numbers")
        from ..spatial import rotation_matrix

        R = rotation_matrix(_orientation(orientation, f"frame {qualified!r}"))
        self._frames[qualified] = Frame(qualified, body, p, R)
        return qualified

    def add_marker(self, name, body, position, weight=1.0, label=None):
        """A marker on ``body`` at ``position`` (3,) m; ``label`` in the trial file."""
        _check_name(name, "marker")
        self._body_index(body, f"marker {name!r}")
        if any(m.name == name for m in self._markers):
            raise ModelError(f"marker {name!r} is defined twice")
        if not (np.isfinite(weight) and weight >= 0):
            raise ModelError(f"marker {name!r}: weight must be >= 0, got {weight}")
        p = np.asarray(position, dtype=float)
        if p.shape != (3,):
            raise ModelError(f"marker {name!r}: position must be 3 numbers")
        self._markers.append(Marker(name, body, p, float(weight), label or name))
        return name

    def frame(self, qualified):
        """The Frame named "body.frame" (a bare body name means its origin)."""
        if not isinstance(qualified, str):
            raise ModelError(f"expected a frame or point name ('body.frame'), got {qualified!r}")
        if "." not in qualified:
            qualified = f"{qualified}.origin"
        if qualified not in self._frames:
            raise ModelError(f"unknown frame/point {qualified!r}; known: {sorted(self._frames)}")
        return self._frames[qualified]

    # -- measures ---------------------------------------------------------------------
    def point(self, qualified, name=""):
        """PointPosition measure of a frame origin (3 rows, m)."""
        f = self.frame(qualified)
        return PointPosition(self._body_index(f.body), f.p_BF, name=name or f.name)

    def vector(self, from_point, to_point, expressed_in=None, name=""):
        """RelativeVector from one point to another, in ``expressed_in``'s frame (a body
        name or a qualified frame whose body is used; world if None)."""
        k = None
        if expressed_in is not None and not isinstance(expressed_in, str):
            raise ModelError(f"expressed_in: expected a body or frame name, got {expressed_in!r}")
        if expressed_in is not None:
            k = self._body_index(self.frame(expressed_in).body if "." in expressed_in else expressed_in)
        return RelativeVector(self.point(from_point), self.point(to_point), k, name=name)

    def distance(self, point_a, point_b, name=""):
        return Distance(self.point(point_a), self.point(point_b), name=name)

    def angles(self, frame_a, frame_b, name=""):
        """x-y-z Cardan angles of frame_b relative to frame_a (3 rows, rad)."""
        fa, fb = self.frame(frame_a), self.frame(frame_b)
        return RelativeAngles(self._body_index(fa.body), fa.R_BF, self._body_index(fb.body), fb.R_BF, name=name)

    def axis_dot(self, frame_a, axis_a, frame_b, axis_b, name=""):
        fa, fb = self.frame(frame_a), self.frame(frame_b)
        return AxisDot(self._body_index(fa.body), fa.R_BF @ axis_a, self._body_index(fb.body), fb.R_BF @ axis_b, name=name)

    def plane_distance(self, plane_frame, point, name=""):
        """Signed distance of ``point`` from the plane through ``plane_frame``'s origin
        with normal z of ``plane_frame`` (1 row, m)."""
        fa = self.frame(plane_frame)
        vec = self.vector(plane_frame, point, expressed_in=plane_frame)
        return Linear([(fa.R_BF[:, 2][None, :], vec)], name=name)

    def add_measure(self, name, measure: Measure):
        """Register a named measure (for drivers, outputs and FDK DOFs by name)."""
        _check_name(name, "measure")
        if name in self._measures:
            raise ModelError(f"measure {name!r} is defined twice")
        measure.name = name
        self._measures[name] = measure
        return measure

    def measure(self, name):
        if not isinstance(name, str) or name not in self._measures:
            raise ModelError(f"unknown measure {name!r}; known: {sorted(self._measures)}")
        return self._measures[name]

    # -- constraints ------------------------------------------------------------------
    def _add_constraint(self, c):
        if any(x.name == c.name for x in self._constraints):
            raise ModelError(f"constraint {c.name!r} is defined twice")
        self._constraints.append(c)
        return c

    def add_joint(self, name, type, parent, child, normal=None):
        """A joint between two frames (JOINT_TYPES).

        weld: all 6 relative DOFs locked; spherical: origins coincide; revolute: origins
        coincide and z axes stay aligned (rotation about z); prismatic: sliding along
        z of the parent frame, no relative rotation; point_on_plane: the child origin
        stays on the plane through the parent origin normal to z (or ``normal``, (3,)
        in the parent frame).
        """
        _check_name(name, "joint")
        if type not in JOINT_TYPES[:-1]:
            raise ModelError(f"joint {name!r}: unknown type {type!r}; expected one of {JOINT_TYPES[:-1]}")
        fa, fb = self.frame(parent), self.frame(child)
        if fa.body == fb.body:
            raise ModelError(f"joint {name!r}: parent and child are on the same body {fa.body!r}")
        ia, ib = self._body_index(fa.body), self._body_index(fb.body)
        Ra, Rb = fa.R_BF, fb.R_BF
        vec = self.vector(parent, child, expressed_in=parent)
        rows, names = [], []
        # relative vector of the origins, expressed in the parent frame F_a
        rel_Fa = Linear([(Ra.T, vec)])

        def dot(u, w, label):
            rows.append((np.ones((1, 1)), AxisDot(ia, Ra @ u, ib, Rb @ w)))
            names.append(f"{name}.{label}")

        if type == "point_on_plane":
            n = _EZ if normal is None else np.asarray(normal, float) / np.linalg.norm(normal)
            measure = Linear([((Ra @ n)[None, :], vec)])
            names = [f"{name}.n"]
        else:
            pos_rows = [0, 1, 2] if type != "prismatic" else [0, 1]
            measure_parts = [(np.eye(3)[pos_rows], rel_Fa)]
            names = [f"{name}.{'xyz'[r]}" for r in pos_rows]
            if type in ("weld", "prismatic"):
                dot(_EY, _EZ, "rx")
                dot(_EZ, _EX, "ry")
                dot(_EX, _EY, "rz")
            elif type == "revolute":
                dot(_EZ, _EX, "zx")
                dot(_EZ, _EY, "zy")
            measure = _stack(measure_parts + [(C, m) for C, m in rows])
        return self._add_constraint(
            Constraint(name, measure, JOINT, np.zeros(measure.size), None, True, tuple(names), type)
        )

    def add_constraint(self, name, measure, value=None, components=None, reaction=True):
        """Generic constraint ``measure = value`` (value in SI units, default 0)."""
        _check_name(name, "constraint")
        measure = self._select(measure, components)
        value = np.zeros(measure.size) if value is None else np.atleast_1d(np.asarray(value, dtype=float))
        if value.shape != (measure.size,):
            raise ModelError(f"constraint {name!r}: value has {value.size} entries, measure has {measure.size}")
        return self._add_constraint(
            Constraint(name, measure, JOINT, value, None, reaction, _row_names(name, measure.size), "generic")
        )

    def add_driver(self, name, measure, function: TimeFunction, components=None, reaction=False):
        """Prescribe ``measure`` (optionally selected ``components``) as ``function(t)``."""
        _check_name(name, "driver")
        measure = self._select(measure, components)
        if not isinstance(function, TimeFunction):
            function = Constant(function)
        if function.size != measure.size:
            raise ModelError(
                f"driver {name!r}: function gives {function.size} values, the measure has {measure.size}"
            )
        return self._add_constraint(
            Constraint(name, measure, DRIVER, np.zeros(measure.size), function, reaction,
                       _row_names(name, measure.size), "driver")
        )

    def add_fdk_dof(self, name, measure, initial=0.0, component=None, **settings):
        """Declare an FDK DOF: a scalar measure whose value α is an input (m or rad)."""
        _check_name(name, "FDK DOF")
        measure = self._select(measure, None if component is None else [component])
        if measure.size != 1:
            raise ModelError(f"FDK DOF {name!r}: the measure must be scalar (select a component)")
        if any(d.name == name for d in self._fdk):
            raise ModelError(f"FDK DOF {name!r} is defined twice")
        self._fdk.append(FDKDof(name, measure, float(initial), dict(settings)))

    def _select(self, measure, components):
        if isinstance(measure, str):
            measure = self.measure(measure)
        if components is None:
            return measure
        components = list(components)
        if any(isinstance(c, bool) or not isinstance(c, (int, np.integer)) or not (0 <= c < measure.size)
               for c in components):
            raise ModelError(f"measure {measure.name!r} has {measure.size} components; got {components}")
        return Linear([(np.eye(measure.size)[components], measure)], name=measure.name)

    # -- build ------------------------------------------------------------------------
    def build(self) -> Model:
        """Validate and freeze. Assigns q̂ columns to moving bodies in declaration order."""
        bodies, col = [], 0
        for i, b in enumerate(self._bodies):
            column = -1 if b["fixed"] else col
            col += 0 if b["fixed"] else 6
            bodies.append(
                Body(b["name"], b["mass"], b["inertia"], b["position"], b["quat"], b["fixed"],
                     b["equilibrium"], i, column)
            )
        names = {b.name: i for i, b in enumerate(bodies)}
        markers = MarkerSet(
            tuple(m.name for m in self._markers),
            tuple(m.label for m in self._markers),
            np.array([names[m.body] for m in self._markers], dtype=int),
            np.array([m.p_BM for m in self._markers], dtype=float).reshape(-1, 3),
            np.array([m.weight for m in self._markers], dtype=float),
        )
        labels = [m.label for m in self._markers]
        dup = {x for x in labels if labels.count(x) > 1}
        if dup:
            raise ModelError(f"markers share trial labels {sorted(dup)}")
        if col == 0:
            raise ModelError(f"model {self.name!r} has no moving body")
        return Model(
            self.name, tuple(bodies), dict(self._frames), markers, dict(self._measures),
            tuple(self._constraints), tuple(self._fdk), self.gravity_W.copy(), dict(self.elements), self.source,
        )


def _stack(parts):
    """Stack (C_j, measure_j) blocks vertically into one Linear measure."""
    total = sum(C.shape[0] for C, _ in parts)
    terms, r = [], 0
    for C, m in parts:
        big = np.zeros((total, m.size))
        big[r : r + C.shape[0]] = C
        terms.append((big, m))
        r += C.shape[0]
    return Linear(terms)


def _row_names(name, size):
    return (name,) if size == 1 else tuple(f"{name}[{k}]" for k in range(size))
