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

from ..numerics.spatial import normalize_quat, quat_from_matrix
from .components import GROUND, Body, Frame, Marker
from .constraints import DRIVER, JOINT, Constraint, FDKDof, MarkerSet
from .measures import AxisDot, Distance, Linear, Measure, PointPosition, RelativeAngles, RelativeVector
from .model import Model, ModelError
from .joint_records import JointRecord, record_joint
from .names import check_name, label_problem
from .settings import AnalysisSettings
from .timefunctions import Constant, TimeFunction

JOINT_TYPES = ("weld", "spherical", "revolute", "prismatic", "point_on_plane", "generic")

_EX, _EY, _EZ = np.eye(3)


def _check_name(name, what):
    """A name of a body, frame, marker, measure or constraint: non-empty text without
    '.', outer spaces or what :func:`~openfdk.model.names.name_problem` refuses."""
    if not isinstance(name, str) or not name or "." in name or name.strip() != name:
        raise ModelError(f"{what} name {name!r} must be a non-empty string without '.' or spaces")
    check_name(name, what)


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
        self.elements = {}  # force elements and settings by kind while building (Model fields when built)
        self.source = ""
        self._add_body_record(GROUND, 0.0, np.zeros((3, 3)), np.zeros(3), None, fixed=True, equilibrium=False)

    # -- bodies and frames -----------------------------------------------------------
    def _body_index(self, name, what="body"):
        for i, b in enumerate(self._bodies):
            if b["name"] == name:
                return i
        known = [b["name"] for b in self._bodies]
        raise ModelError(f"{what}: unknown body {name!r}; known bodies: {known}")

    def _add_body_record(self, name, mass, inertia, position, orientation, fixed, equilibrium, as_given=False):
        self._bodies.append(
            dict(
                name=name, mass=mass, inertia=inertia, position=position,
                quat=_orientation(orientation, f"body {name!r}"), fixed=fixed, equilibrium=equilibrium,
                inertia_as_given=as_given,
            )
        )
        self._frames[f"{name}.origin"] = Frame(f"{name}.origin", name, np.zeros(3), np.eye(3))

    def add_body(self, name, mass, inertia, position=(0, 0, 0), orientation=None, fixed=False, equilibrium=True,
                 inertia_as_given=False):
        """Add a rigid body.

        mass : kg (≥ 0 for a moving body: 0 for a massless link); inertia : (3,) principal moments or (3, 3)
        kg m² about the centre of mass in the body frame; position : (3,) m of the
        centre of mass (the body frame origin) in the reference pose; orientation :
        quaternion (4,) or rotation matrix R_WB (3, 3); fixed : fixed to the world;
        inertia_as_given : an inertia no rigid body has (the triangle inequality) is used
        with a warning instead of refused (:func:`~openfdk.model.plausibility.check_mass_properties`).
        """
        _check_name(name, "body")
        if any(b["name"] == name for b in self._bodies):
            raise ModelError(f"body {name!r} is defined twice")
        inertia = np.asarray(inertia, dtype=float)
        if inertia.shape == (3,):
            inertia = np.diag(inertia)
        if inertia.shape != (3, 3):
            raise ModelError(f"body {name!r}: inertia must be 3 principal moments or a 3x3 matrix")
        if not fixed:  # a massless body or a point mass (zero inertia) has no inertial forces
            if not (np.isfinite(mass) and mass >= 0):
                raise ModelError(f"body {name!r}: mass must be >= 0 kg, got {mass}")
            scale = float(np.max(np.abs(inertia))) if np.all(np.isfinite(inertia)) else np.inf
            if not np.isfinite(scale) or not np.allclose(inertia, inertia.T) \
                    or np.any(np.linalg.eigvalsh(inertia / (scale or 1.0)) < -1e-12):
                raise ModelError(f"body {name!r}: inertia must be symmetric positive semi-definite")
        position = np.asarray(position, dtype=float)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ModelError(f"body {name!r}: position must be 3 finite numbers")
        self._add_body_record(name, float(mass), inertia, position, orientation, bool(fixed), bool(equilibrium),
                              bool(inertia_as_given))
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
        from ..numerics.spatial import rotation_matrix

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
        if label_problem(label):
            raise ModelError(f"marker {name!r}: {label_problem(label)}")
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
        """Vector from one point to another (3 rows, m) expressed in ``expressed_in``: a
        body name (the body's axes), a qualified frame "body.frame" (that frame's axes:
        w_F = R_BFᵀ w_B) or None (world axes)."""
        if expressed_in is None:
            return RelativeVector(self.point(from_point), self.point(to_point), None, name=name)
        f = self.frame(expressed_in)
        vec = RelativeVector(self.point(from_point), self.point(to_point), self._body_index(f.body), name=name)
        if "." not in expressed_in or np.array_equal(f.R_BF, np.eye(3)):
            return vec
        return Linear([(f.R_BF.T, vec)], name=name)

    def distance(self, point_a, point_b, name=""):
        return Distance(self.point(point_a), self.point(point_b), name=name)

    def angles(self, frame_a, frame_b, name="", sequence="xyz"):
        """Angles of frame_b relative to frame_a (3 rows, rad) in an intrinsic Euler or
        Cardan ``sequence`` (default x-y-z; :mod:`openfdk.model.rotation_angles`)."""
        fa, fb = self.frame(frame_a), self.frame(frame_b)
        if sequence == "xyz":
            return RelativeAngles(self._body_index(fa.body), fa.R_BF, self._body_index(fb.body), fb.R_BF, name=name)
        from .rotation_angles import RotationAngles

        try:
            return RotationAngles(self._body_index(fa.body), fa.R_BF, self._body_index(fb.body), fb.R_BF,
                                  sequence, name=name)
        except ValueError as exc:
            raise ModelError(str(exc)) from None

    def jcs_angles(self, parent, child, joint="knee", side="right", name=""):
        """Joint-coordinate-system angles (Grood & Suntay 1983; ISB, Wu et al. 2002/2005)
        of the anatomical frame ``child`` in ``parent`` (3 rows, rad): knee/hip/ankle
        z-x-y (flexion, adduction, internal rotation; knee flexion is the negative
        rotation about z), shoulder y-x-y; ``side`` "left" negates angles 2 and 3
        (docs/model-file.md, measures)."""
        from .rotation_angles import JCS_CONVENTIONS, RotationAngles

        if joint not in JCS_CONVENTIONS:
            raise ModelError(f"JCS angles: unknown joint convention {joint!r}; expected one of {sorted(JCS_CONVENTIONS)}")
        if side not in ("right", "left"):
            raise ModelError(f"JCS angles: side must be 'right' or 'left', got {side!r}")
        fa, fb = self.frame(parent), self.frame(child)
        sequence, _, sign = JCS_CONVENTIONS[joint]
        if side == "left" and joint != "shoulder":
            sign = (sign[0], -sign[1], -sign[2])
        return RotationAngles(self._body_index(fa.body), fa.R_BF, self._body_index(fb.body), fb.R_BF,
                              sequence, sign, name=name)

    def axis_dot(self, frame_a, axis_a, frame_b, axis_b, name=""):
        fa, fb = self.frame(frame_a), self.frame(frame_b)
        return AxisDot(self._body_index(fa.body), fa.R_BF @ axis_a, self._body_index(fb.body), fb.R_BF @ axis_b, name=name)

    def plane_distance(self, plane_frame, point, name=""):
        """Signed distance of ``point`` from the plane through ``plane_frame``'s origin
        with normal z of ``plane_frame`` (1 row, m)."""
        vec = self.vector(plane_frame, point, expressed_in=plane_frame)
        return Linear([(_EZ[None, :], vec)], name=name)

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
        check_name(c.name, "constraint")
        if any(x.name == c.name for x in self._constraints):
            raise ModelError(f"constraint {c.name!r} is defined twice")
        self._constraints.append(c)
        return c

    def add_joint(self, name, type, parent, child, normal=None, fdk=None, reaction=None):
        """A joint between two frames (JOINT_TYPES).

        weld: all 6 relative DOFs locked; spherical: origins coincide; revolute: origins
        coincide and z axes stay aligned (rotation about z); prismatic: sliding along
        z of the parent frame, no relative rotation; point_on_plane: the child origin
        stays on the plane through the parent origin normal to z (or ``normal``, (3,)
        in the parent frame).

        Rows are labelled x, y, z (child origin in the parent frame), rx, ry, rz (weld,
        prismatic), zx, zy (revolute), n (point_on_plane); row names are "{name}.{label}".
        fdk : labels of rows that become FDK DOFs instead of constraints (a list, or a
            dict label -> FDK settings such as ``initial``, ``max_step``); the DOF
            ``{name}_{label}`` is that row's measure, and the row carries no reaction.
        reaction : dict label -> bool, switches the reaction of single rows (default on).

        Also registers the joint's measures by name (:meth:`_register_joint_measures`):
        ``{name}.position``, ``{name}.angles`` and, for a revolute, ``{name}.angle``, for a
        prismatic, ``{name}.slide``.
        """
        _check_name(name, "joint")
        if type not in JOINT_TYPES[:-1]:
            raise ModelError(f"joint {name!r}: unknown type {type!r}; expected one of {JOINT_TYPES[:-1]}")
        fa, fb = self.frame(parent), self.frame(child)
        if fa.body == fb.body:
            raise ModelError(f"joint {name!r}: parent and child are on the same body {fa.body!r}")
        ia, ib = self._body_index(fa.body), self._body_index(fb.body)
        Ra, Rb = fa.R_BF, fb.R_BF
        # relative vector of the origins, expressed in the parent frame F_a
        rel_Fa = self.vector(parent, child, expressed_in=parent)
        rows = []  # (label, (1, size) coefficients, measure)

        def dot(u, w, label):
            rows.append((label, np.ones((1, 1)), AxisDot(ia, Ra @ u, ib, Rb @ w)))

        if type == "point_on_plane":
            n = _EZ if normal is None else np.asarray(normal, float) / np.linalg.norm(normal)
            rows.append(("n", n[None, :], rel_Fa))
        else:
            for r in [0, 1, 2] if type != "prismatic" else [0, 1]:
                rows.append(("xyz"[r], np.eye(3)[[r]], rel_Fa))
            if type in ("weld", "prismatic"):
                dot(_EY, _EZ, "rx")
                dot(_EZ, _EX, "ry")
                dot(_EX, _EY, "rz")
            elif type == "revolute":
                dot(_EZ, _EX, "zx")
                dot(_EZ, _EY, "zy")
        labels = [r[0] for r in rows]
        fdk_settings = _joint_row_options(name, "fdk", fdk, labels)
        reactions = _joint_row_options(name, "reaction", reaction, labels)
        for label, on in reactions.items():
            if not isinstance(on, bool):
                raise ModelError(f"joint {name!r}: reaction of row {label!r} must be true or false, got {on!r}")
            if label in fdk_settings and on:
                raise ModelError(f"joint {name!r}: row {label!r} is an FDK DOF and cannot carry a reaction")
        self._register_joint_measures(name, type, parent, child, rel_Fa)
        record_joint(self, JointRecord(name, type, self.frame(parent).name, self.frame(child).name,  # qualified
                                       None if type != "point_on_plane" else n, tuple(fdk_settings)))
        for label in fdk_settings:
            C, m = next((C, m) for lab, C, m in rows if lab == label)
            settings = dict(fdk_settings[label] or {})
            initial = float(settings.pop("initial", 0.0))
            self.add_fdk_dof(f"{name}_{label}", Linear([(C, m)], name=f"{name}.{label}"), initial, **settings)
        kept = [r for r in rows if r[0] not in fdk_settings]
        if not kept:
            return None
        with_reaction = [r for r in kept if reactions.get(r[0], True)]
        without = [r for r in kept if not reactions.get(r[0], True)]
        first = None
        # rows without reaction go to their own block "{name}.passive" (or "{name}" alone)
        for carries, group in ((True, with_reaction), (False, without)):
            if not group:
                continue
            cname = f"{name}.passive" if (not carries and with_reaction) else name
            parts = []  # consecutive rows of one measure share one block
            for _, C, m in group:
                if parts and parts[-1][1] is m:
                    parts[-1] = (np.vstack([parts[-1][0], C]), m)
                else:
                    parts.append((C, m))
            measure = _stack(parts)
            c = self._add_constraint(Constraint(cname, measure, JOINT, np.zeros(measure.size), None, carries,
                                                tuple(f"{name}.{r[0]}" for r in group), type))
            first = first or c
        return first

    def _register_joint_measures(self, name, type, parent, child, rel_Fa):
        """Named measures of a joint: ``name.position`` (3, m, child origin in the parent
        frame), ``name.angles`` (3, rad, x-y-z Cardan angles of the child frame in the
        parent frame), ``name.angle`` (revolute: rotation about z, rad), ``name.slide``
        (prismatic: translation along the parent z, m)."""
        angles = self.angles(parent, child)
        found = {f"{name}.position": rel_Fa, f"{name}.angles": angles}
        if type == "revolute":
            found[f"{name}.angle"] = Linear([(_EZ[None, :], angles)])
        if type == "prismatic":
            found[f"{name}.slide"] = Linear([(_EZ[None, :], rel_Fa)])
        for key, m in found.items():
            if key in self._measures:
                raise ModelError(f"joint {name!r}: measure {key!r} is already defined")
            m = Linear([(np.eye(m.size), m)], name=key) if m.name else m
            m.name = key
            self._measures[key] = m

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
                     b["equilibrium"], i, column, b["inertia_as_given"])
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
        self._check_all_names()
        return Model(
            self.name, tuple(bodies), dict(self._frames), markers, dict(self._measures),
            tuple(self._constraints), tuple(self._fdk), self.gravity_W.copy(), **self._typed_elements(),
            source=self.source,
        )

    #: element kinds collected in ``self.elements`` -> Model field
    ELEMENT_FIELDS = ("muscles", "ligaments", "springs", "contacts", "loads", "unilateral_reactions", "visuals",
                      "coordinates", "tasks", "external_loads", "actuators", "joints")
    SETTING_FIELDS = {"analysis": "kinematics", "recruitment": "recruitment", "fdk": "fdk", "units": "units",
                      "ground_reactions": "ground_reactions", "joint_reaction": "joint_reaction"}

    def _check_all_names(self):
        """Every name the model will carry — also of items put into the builder without
        its ``add_…`` methods — passes :func:`~openfdk.model.names.name_problem`: names
        become file names and XML in exports."""
        named = [("body", r["name"]) for r in self._bodies] + [("frame", f) for f in self._frames]
        named += [("marker", m.name) for m in self._markers] + [("measure", m) for m in self._measures]
        named += [("constraint", c.name) for c in self._constraints] + [("FDK DOF", d.name) for d in self._fdk]
        named += [("wrapping surface", w) for w in self.__dict__.get("wrap_surfaces", {})]
        for kind, items in self.elements.items():
            if isinstance(items, (tuple, list)):
                named += [(kind.rstrip("s").replace("_", " "), getattr(e, "name", None)) for e in items]
        for what, name in named:
            check_name(name, what)
        for m in self._markers:
            if label_problem(m.label):
                raise ModelError(f"marker {m.name!r}: {label_problem(m.label)}")

    def _typed_elements(self):
        """Model keyword arguments from the kinds collected in ``self.elements``."""
        rest = dict(self.elements)
        out = {kind: tuple(rest.pop(kind, ())) for kind in self.ELEMENT_FIELDS}
        unknown = sorted(set(rest) - set(self.SETTING_FIELDS))
        if unknown:
            raise ModelError(f"unknown force-element or settings kinds {unknown}; known: "
                             f"{list(self.ELEMENT_FIELDS) + list(self.SETTING_FIELDS)}")
        return out

    def settings(self) -> AnalysisSettings:
        """The analysis settings collected while building (model-file sections
        ``analysis``, ``recruitment``, ``fdk``, ``units``; :func:`set_recruitment`), apart
        from the Model that :meth:`build` returns."""
        return AnalysisSettings(**{name: self.elements[kind] for kind, name in self.SETTING_FIELDS.items()
                                   if kind in self.elements})


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


def _joint_row_options(name, key, value, labels):
    """{label: settings} from a list of labels or a mapping label -> settings."""
    if value is None:
        return {}
    if isinstance(value, (list, tuple)):
        value = {label: None for label in value}
    if not isinstance(value, dict):
        raise ModelError(f"joint {name!r}: {key} must be a list of row labels or a mapping, got {value!r}")
    bad = [k for k in value if k not in labels]
    if bad:
        raise ModelError(f"joint {name!r}: {key}: unknown rows {bad}; this joint's rows are {labels}")
    return dict(value)


def _row_names(name, size):
    return (name,) if size == 1 else tuple(f"{name}[{k}]" for k in range(size))
