"""The mandible subject folder: load and validate (format: docs/subject-folder.md).

A subject folder holds ``subject.yaml`` (landmarks, TMJ planes, mandible inertia,
muscles, ligaments, contact surfaces, dental braces) and the STL files it names. All
positions are in the subject frame at the reference pose: origin midway between the
most superior points of the two condyles, x anterior, y left, z up (Frankfurt
horizontal); skull and mandible frames coincide there (docs/design.md §2). The file declares
its length unit (m, cm, mm; default mm) and angle unit (deg, rad; default deg); mass is
kg, inertia kg m², force N. :func:`load_subject` converts everything to SI once.

Every problem raises :class:`SubjectError` naming the file and the entry, e.g.
``subject.yaml: muscles.masseter_r: missing 'max_isometric_force' (N)``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ..io.yamlfile import YamlContext, read_yaml, unknown_key
from ..numerics.spatial import rotation_matrix_xyz
from .protocol import PROTOCOL_KEYS, StudyProtocol, parse_protocol

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MUSCLE_DEFAULTS",
    "REQUIRED_LANDMARKS",
    "SUBJECT_FILE",
    "SURFACE_BODIES",
    "Brace",
    "InertialProperties",
    "LigamentSpec",
    "MuscleSpec",
    "Plane",
    "Subject",
    "SubjectError",
    "SurfaceSpec",
    "load_subject",
]

SUBJECT_FILE = "subject.yaml"
FORMAT_NAME = "openfdk-subject"
FORMAT_VERSION = 1
LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
ANGLE_UNITS = {"rad": 1.0, "deg": np.pi / 180.0}
REQUIRED_LANDMARKS = ("condyle_top_r", "condyle_top_l", "incisal_point",
                      "molar_r", "molar_l", "premolar_r", "premolar_l")
#: contact surfaces and the body each is fixed to, with the direction its normals face
SURFACE_BODIES = {"condyle_r": "mandible", "condyle_l": "mandible", "fossa_r": "skull", "fossa_l": "skull"}
_SURFACE_FACING = {"mandible": +1.0, "skull": -1.0}      # mean normal · z sign (up / down)
#: Hill parameters a muscle may omit (de Zee et al. 2007 common values); angle in rad
MUSCLE_DEFAULTS = {"tendon_strain_at_max_force": 0.053, "pennation_angle_at_optimal": 0.0,
                   "fast_fibre_fraction": 0.4, "passive_shape_factor": 3.0}
_MUSCLE_REQUIRED = {"origin": "length unit", "insertion": "length unit", "max_isometric_force": "N",
                    "optimal_fibre_length": "length unit", "tendon_slack_length": "length unit"}
_TOP_KEYS = {"format", "version", "name", "description", "units", "cartilage_offset", "landmarks",
             "tmj_planes", "mandible", "muscle_defaults", "muscles", "ligaments", "surfaces", "braces",
             *PROTOCOL_KEYS}
_TOP_REQUIRED = ("format", "version", "landmarks", "tmj_planes", "mandible", "muscles", "ligaments",
                 "surfaces", "braces")
_FRAME_TOLERANCE = 1e-3   # m: origin midway between the condyle tops, tops level in x


class SubjectError(ValueError):
    """A subject folder is incomplete or invalid; the message names the file and entry."""


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Plane:
    """A plane fixed in the skull: ``point`` (3,) m and unit ``normal`` (3,) (pointing up)."""

    point: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True)
class InertialProperties:
    """``mass`` kg, ``center_of_mass`` (3,) m, ``inertia`` (3, 3) kg m² about the centre of
    mass, subject axes."""

    mass: float
    center_of_mass: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class MuscleSpec:
    """A muscle–tendon unit from ``origin`` (skull) to ``insertion`` (mandible), (3,) m each.

    ``max_isometric_force`` N, ``optimal_fibre_length`` m, ``tendon_slack_length`` m,
    ``pennation_angle_at_optimal`` rad; the field names are those of
    :class:`openfdk.forces.hill.Hill3ElementMuscle` (see :meth:`hill_parameters`).
    """

    name: str
    origin: np.ndarray
    insertion: np.ndarray
    max_isometric_force: float
    optimal_fibre_length: float
    tendon_slack_length: float
    tendon_strain_at_max_force: float
    pennation_angle_at_optimal: float
    fast_fibre_fraction: float
    passive_shape_factor: float

    def hill_parameters(self) -> dict:
        """Keyword arguments for ``Hill3ElementMuscle`` (SI)."""
        return {k: getattr(self, k) for k in ("max_isometric_force", "optimal_fibre_length",
                                              "tendon_slack_length", "tendon_strain_at_max_force",
                                              "pennation_angle_at_optimal", "fast_fibre_fraction",
                                              "passive_shape_factor", "name")}


@dataclass(frozen=True)
class LigamentSpec:
    """A ligament line element, ``origin`` (skull) and ``insertion`` (mandible) (3,) m;
    ``reference_length`` m = its length in the closed-mouth reference pose."""

    name: str
    origin: np.ndarray
    insertion: np.ndarray
    reference_length: float


@dataclass(frozen=True)
class SurfaceSpec:
    """A contact surface: triangle mesh fixed to ``body`` ('mandible' or 'skull').

    ``vertices`` (n, 3) m in the subject frame at the reference pose, ``faces`` (m, 3)
    int, normals (right-hand rule) toward the joint space; ``path`` is the STL file.
    """

    name: str
    body: str
    path: Path
    vertices: np.ndarray
    faces: np.ndarray


@dataclass(frozen=True)
class Brace:
    """A dental brace on ``body``: marker ``labels`` and nominal ``positions`` (k, 3) m in
    the subject frame at the reference pose; ``plate_size`` m, ``marker_diameter`` m."""

    body: str
    labels: tuple
    positions: np.ndarray
    plate_size: float | None = None
    marker_diameter: float | None = None

    def position(self, label: str) -> np.ndarray:
        """Nominal position (3,) m of marker ``label``."""
        return self.positions[self.labels.index(label)]


@dataclass(frozen=True)
class Subject:
    """A validated mandible subject (SI units; positions in the subject frame S at the
    reference pose, where the skull and mandible frames coincide).

    Attributes: ``directory``, ``name``, ``description``; ``landmarks`` name → (3,) m;
    ``tmj_planes`` 'r'/'l' → :class:`Plane`; ``mandible`` :class:`InertialProperties`;
    ``muscles`` / ``ligaments`` tuples of specs; ``surfaces`` name → :class:`SurfaceSpec`
    (condyle_r, condyle_l, fossa_r, fossa_l); ``braces`` 'skull'/'mandible' →
    :class:`Brace`; ``cartilage_offset`` m (the model's uniform condyle offset);
    ``length_unit`` of the file.
    """

    directory: Path
    name: str
    description: str
    landmarks: MappingProxyType
    tmj_planes: MappingProxyType
    mandible: InertialProperties
    muscles: tuple
    ligaments: tuple
    surfaces: MappingProxyType
    braces: MappingProxyType
    cartilage_offset: float
    length_unit: str
    protocol: StudyProtocol | None = None

    def condyle_top(self, side: str) -> np.ndarray:
        """Most superior condyle point (3,) m, side 'r' or 'l'."""
        return self.landmarks[f"condyle_top_{side}"]

    def condyle_point(self, side: str) -> np.ndarray:
        """The condyle point whose kinematics the study compares (3,) m, side 'r' or 'l':
        the landmark named in ``condyle_point`` (default the condyle top)."""
        name = self.protocol.condyle_points[side] if self.protocol is not None else f"condyle_top_{side}"
        return self.landmarks[name]

    @property
    def hyoid_muscles(self):
        """Muscle names listed in the ``hyoid`` section, or None (see :mod:`.models`)."""
        return self.protocol.hyoid_muscles if self.protocol is not None else None

    @property
    def marker_labels(self) -> tuple:
        """Skull brace labels, then mandible brace labels."""
        return self.braces["skull"].labels + self.braces["mandible"].labels

    def muscle(self, name: str) -> MuscleSpec:
        for m in self.muscles:
            if m.name == name:
                return m
        raise KeyError(f"no muscle {name!r} in subject {self.name!r}")


# --------------------------------------------------------------------------------------
# Reading helpers: every error names file and entry
# --------------------------------------------------------------------------------------

class _Context(YamlContext):
    """The shared YAML context (:class:`~openfdk.io.yamlfile.YamlContext`) raising
    :class:`SubjectError`; vectors are 3 numbers unless told."""

    error_type = SubjectError

    def __init__(self, file: Path, length: float, angle: float):
        super().__init__(file, length, angle, base_dir=Path(file).parent)
        self.file = file

    def vector(self, value, where: str, n: int = 3) -> np.ndarray:
        return super().vector(value, where, n=n)

    def point(self, value, where: str) -> np.ndarray:
        return _readonly(self.vector(value, where) * self.length)


def _units(data: dict, file: Path) -> tuple[str, float, float]:
    units = data.get("units", {}) or {}
    if not isinstance(units, dict):
        raise SubjectError(f"{file}: units: expected a mapping like {{length: mm, angle: deg}}")
    for key in units:
        if key not in ("length", "angle"):
            raise SubjectError(f"{file}: units.{key}: {unknown_key(key, ('angle', 'length'))} "
                               f"(mass is kg, inertia kg m², force N)")
    length = str(units.get("length", "mm"))
    angle = str(units.get("angle", "deg"))
    if length not in LENGTH_UNITS:
        raise SubjectError(f"{file}: units.length: unknown length unit {length!r}; expected one of "
                           f"{list(LENGTH_UNITS)}")
    if angle not in ANGLE_UNITS:
        raise SubjectError(f"{file}: units.angle: unknown angle unit {angle!r}; expected one of "
                           f"{list(ANGLE_UNITS)}")
    return length, LENGTH_UNITS[length], ANGLE_UNITS[angle]


# --------------------------------------------------------------------------------------
# Sections
# --------------------------------------------------------------------------------------

def _landmarks(ctx: _Context, data) -> dict:
    data = ctx.mapping(data, "landmarks", required=REQUIRED_LANDMARKS)
    landmarks = {str(k): ctx.point(v, f"landmarks.{k}") for k, v in data.items()}
    r, l = landmarks["condyle_top_r"], landmarks["condyle_top_l"]
    mid = 0.5 * (r + l)
    if np.max(np.abs(mid)) > _FRAME_TOLERANCE or abs(l[0] - r[0]) > _FRAME_TOLERANCE or l[1] <= r[1]:
        raise ctx.error("landmarks", "the subject frame must have its origin midway between "
                        "condyle_top_r and condyle_top_l, x anterior, y from right to left "
                        f"(midpoint {1e3 * mid} mm, left − right {1e3 * (l - r)} mm); "
                        "transform the data into the subject frame (docs/subject-folder.md)")
    return landmarks


def _planes(ctx: _Context, data) -> dict:
    data = ctx.mapping(data, "tmj_planes", allowed={"r", "l"}, required=("r", "l"))
    planes = {}
    for side, entry in data.items():
        where = f"tmj_planes.{side}"
        entry = ctx.mapping(entry, where, allowed={"point", "normal"}, required=("point", "normal"))
        normal = ctx.vector(entry["normal"], f"{where}.normal")
        if np.linalg.norm(normal) < 1e-9:
            raise ctx.error(f"{where}.normal", "is the zero vector")
        planes[side] = Plane(ctx.point(entry["point"], f"{where}.point"),
                             _readonly(normal / np.linalg.norm(normal)))
    return planes


def _mandible(ctx: _Context, data) -> InertialProperties:
    data = ctx.mapping(data, "mandible", allowed={"mass", "center_of_mass", "inertia"},
                       required=("mass", "center_of_mass", "inertia"))
    mass = ctx.number(data["mass"], "mandible.mass", "kg", positive=True)
    com = ctx.point(data["center_of_mass"], "mandible.center_of_mass")
    raw = data["inertia"]
    where = "mandible.inertia"
    if isinstance(raw, (list, tuple)) and len(raw) == 3 and all(isinstance(r, (list, tuple)) for r in raw):
        inertia = np.array([ctx.vector(r, f"{where}[{i}]") for i, r in enumerate(raw)])
    else:
        inertia = np.diag(ctx.vector(raw, where))
    if not np.allclose(inertia, inertia.T, rtol=1e-9, atol=1e-12):
        raise ctx.error(where, "must be symmetric (kg m², about the centre of mass)")
    eig = np.linalg.eigvalsh(inertia)
    if eig[0] <= 0 or eig[0] + eig[1] < eig[2] * (1 - 1e-9):
        raise ctx.error(where, f"principal moments {eig} (kg m²) must be positive and satisfy the "
                        "triangle inequality")
    return InertialProperties(mass, com, _readonly(inertia))


def _muscles(ctx: _Context, data, defaults) -> tuple:
    data = ctx.mapping(data, "muscles")
    if not data:
        raise ctx.error("muscles", "no muscles listed")
    allowed = set(_MUSCLE_REQUIRED) | set(MUSCLE_DEFAULTS)
    defaults = dict(MUSCLE_DEFAULTS) | {
        k: ctx.number(v, f"muscle_defaults.{k}") * (ctx.angle if k == "pennation_angle_at_optimal" else 1.0)
        for k, v in ctx.mapping(defaults or {}, "muscle_defaults", allowed=set(MUSCLE_DEFAULTS)).items()}
    muscles = []
    for name, entry in data.items():
        where = f"muscles.{name}"
        entry = ctx.mapping(entry, where, allowed=allowed)
        for key, unit in _MUSCLE_REQUIRED.items():
            if key not in entry:
                raise ctx.error(where, f"missing {key!r} ({unit})")
        values = dict(defaults)
        for key in MUSCLE_DEFAULTS:
            if key in entry:
                scale = ctx.angle if key == "pennation_angle_at_optimal" else 1.0
                values[key] = ctx.number(entry[key], f"{where}.{key}") * scale
        if not 0 <= values["fast_fibre_fraction"] <= 1:
            raise ctx.error(f"{where}.fast_fibre_fraction", "must be in [0, 1]")
        if not 0 <= values["pennation_angle_at_optimal"] < np.pi / 2:
            raise ctx.error(f"{where}.pennation_angle_at_optimal", "must be in [0, 90°)")
        for key in ("tendon_strain_at_max_force", "passive_shape_factor"):
            if values[key] <= 0:
                raise ctx.error(f"{where}.{key}", f"must be > 0, got {values[key]:g}")
        muscles.append(MuscleSpec(
            name=str(name), origin=ctx.point(entry["origin"], f"{where}.origin"),
            insertion=ctx.point(entry["insertion"], f"{where}.insertion"),
            max_isometric_force=ctx.number(entry["max_isometric_force"], f"{where}.max_isometric_force",
                                           "N", positive=True),
            optimal_fibre_length=ctx.length * ctx.number(entry["optimal_fibre_length"],
                                                         f"{where}.optimal_fibre_length", positive=True),
            tendon_slack_length=ctx.length * ctx.number(entry["tendon_slack_length"],
                                                        f"{where}.tendon_slack_length", positive=True),
            **values))
    return tuple(muscles)


def _ligaments(ctx: _Context, data) -> tuple:
    data = ctx.mapping(data if data is not None else {}, "ligaments")
    ligaments = []
    for name, entry in data.items():
        where = f"ligaments.{name}"
        entry = ctx.mapping(entry, where, allowed={"origin", "insertion", "reference_length"},
                            required=("origin", "insertion"))
        origin, insertion = ctx.point(entry["origin"], f"{where}.origin"), ctx.point(entry["insertion"], f"{where}.insertion")
        length = float(np.linalg.norm(insertion - origin))
        if "reference_length" in entry:
            length = ctx.length * ctx.number(entry["reference_length"], f"{where}.reference_length", positive=True)
        if length <= 0:
            raise ctx.error(where, "origin and insertion coincide")
        ligaments.append(LigamentSpec(str(name), origin, insertion, length))
    return tuple(ligaments)


def _check_mesh_size(ctx: _Context, where: str, path: Path):
    """The size limits of :mod:`openfdk.io.limits` before trimesh reads the mesh: a
    binary STL's triangle count from its header, any other file's size."""
    from ..contact.stl import StlError, check_stl_size
    from ..io import limits

    try:
        if path.suffix.lower() in ("", ".stl"):
            check_stl_size(path)
        else:
            limits.check_file_bytes(path, "MESH_FILE_BYTES", "", StlError)
    except StlError as exc:
        raise ctx.error(where, f"mesh file {path.name!r}: {exc}") from None
    except OSError as exc:
        raise ctx.error(where, f"mesh file {path.name!r} cannot be read: {exc.strerror or exc}") from None


def _load_stl(ctx: _Context, where: str, path: Path, scale: float, placement, flip: bool):
    try:
        found, size = path.exists(), (path.stat().st_size if path.is_file() else 0)
    except (OSError, ValueError) as exc:  # name too long, NUL byte
        raise ctx.error(where, f"mesh file {path.name[:80]!r} is not a usable path: {exc}") from None
    if not found:
        raise ctx.error(where, f"mesh file {path.name!r} not found in {path.parent}")
    if size == 0:
        raise ctx.error(where, f"mesh file {path.name!r} is empty")
    _check_mesh_size(ctx, where, path)
    import trimesh

    try:
        mesh = trimesh.load(str(path), file_type=path.suffix.lstrip(".").lower() or "stl",
                            force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for bad files
        raise ctx.error(where, f"mesh file {path.name!r} cannot be read: {exc}") from exc
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=float)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(faces) == 0 or len(vertices) < 3:
        raise ctx.error(where, f"mesh file {path.name!r} has no triangles")
    if not np.all(np.isfinite(vertices)):
        raise ctx.error(where, f"mesh file {path.name!r} has non-finite vertex coordinates")
    if flip:
        faces = faces[:, ::-1]
    vertices = vertices * scale
    if placement is not None:
        vertices = vertices @ placement[0].T + placement[1]
    return _readonly(vertices), np.ascontiguousarray(faces)


def _surfaces(ctx: _Context, data, directory: Path, landmarks: dict, length_unit: str) -> dict:
    data = ctx.mapping(data, "surfaces", allowed=set(SURFACE_BODIES), required=tuple(SURFACE_BODIES))
    surfaces = {}
    for name, entry in data.items():
        where = f"surfaces.{name}"
        entry = ctx.mapping(entry, where, allowed={"file", "units", "placement", "flip_normals"},
                            required=("file",))
        unit = str(entry.get("units", length_unit))
        if unit not in LENGTH_UNITS:
            raise ctx.error(f"{where}.units", f"unknown length unit {unit!r}; expected one of {list(LENGTH_UNITS)}")
        placement = None
        if "placement" in entry:
            p = ctx.mapping(entry["placement"], f"{where}.placement", allowed={"position", "orientation"})
            R = rotation_matrix_xyz(ctx.vector(p.get("orientation", [0, 0, 0]), f"{where}.placement.orientation") * ctx.angle)
            placement = (R, ctx.vector(p.get("position", [0, 0, 0]), f"{where}.placement.position") * ctx.length)
        flip = entry.get("flip_normals", False)
        if not isinstance(flip, bool):
            raise ctx.error(f"{where}.flip_normals", f"expected true or false, got {flip!r}")
        if not isinstance(entry["file"], str) or not entry["file"]:
            raise ctx.error(f"{where}.file", f"expected a file name, got {entry['file']!r}")
        path = directory / entry["file"]
        vertices, faces = _load_stl(ctx, where, path, LENGTH_UNITS[unit], placement, flip)
        body = SURFACE_BODIES[name]
        # normals must face the joint space: up for the condyles, down for the fossae
        cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
        facing = _SURFACE_FACING[body] * np.sum(cross[:, 2])
        if facing <= 0:
            raise ctx.error(where, f"the normals of {path.name!r} point {'down' if body == 'mandible' else 'up'}; "
                            f"they must point toward the joint space ({'up, out of the condyle' if body == 'mandible' else 'down, out of the skull'}); "
                            "set flip_normals: true if the file is wound the other way")
        top = landmarks[f"condyle_top_{name[-1]}"]
        distance = float(np.min(np.linalg.norm(vertices - top, axis=1)))
        if distance > 0.015:
            raise ctx.error(where, f"{path.name!r} lies {1e3 * distance:.1f} mm from condyle_top_{name[-1]} "
                            f"(expected < 15 mm): wrong units ({unit}) or placement?")
        surfaces[name] = SurfaceSpec(name, body, path, vertices, faces)
    return surfaces


def _braces(ctx: _Context, data) -> dict:
    data = ctx.mapping(data, "braces", allowed={"skull", "mandible"}, required=("skull", "mandible"))
    braces, seen = {}, {}
    for body, entry in data.items():
        where = f"braces.{body}"
        entry = ctx.mapping(entry, where, allowed={"markers", "plate_size", "marker_diameter"}, required=("markers",))
        markers = ctx.mapping(entry["markers"], f"{where}.markers")
        if len(markers) < 3:
            raise ctx.error(f"{where}.markers", f"needs at least 3 markers for a rigid fit, got {len(markers)}")
        labels = tuple(str(k) for k in markers)
        for label in labels:
            if label in seen:
                raise ctx.error(f"{where}.markers.{label}", f"label also used on the {seen[label]} brace")
            seen[label] = body
        positions = np.array([ctx.point(markers[k], f"{where}.markers.{k}") for k in markers])
        centred = positions - positions.mean(axis=0)
        if np.linalg.svd(centred, compute_uv=False)[1] < 1e-4:
            raise ctx.error(f"{where}.markers", "markers are (nearly) collinear: no rigid fit possible")
        optional = {k: ctx.length * ctx.number(entry[k], f"{where}.{k}", positive=True)
                    for k in ("plate_size", "marker_diameter") if k in entry}
        braces[body] = Brace(body, labels, _readonly(positions), **optional)
    return braces


def load_subject(directory: str | os.PathLike) -> Subject:
    """Load and validate a subject folder (docs/subject-folder.md).

    Args: directory containing ``subject.yaml`` and the mesh files it names.
    Returns: a frozen :class:`Subject` in SI units.
    Raises: :class:`SubjectError` naming the file and entry of the first problem.
    """
    directory = Path(directory)
    file = directory / SUBJECT_FILE
    if not directory.is_dir():
        raise SubjectError(f"{directory}: no such subject folder")
    if not file.is_file():
        raise SubjectError(f"{file}: missing; a subject folder needs {SUBJECT_FILE} "
                           f"(see docs/subject-folder.md)")
    data = read_yaml(file, SubjectError, "subject file", source=str(file))
    if not isinstance(data, dict):
        raise SubjectError(f"{file}: expected a mapping of sections at the top level, got "
                           f"{type(data).__name__}")
    length_unit, length, angle = _units(data, file)
    ctx = _Context(file, length, angle)
    ctx.mapping(data, "", allowed=_TOP_KEYS, required=_TOP_REQUIRED)
    if data["format"] != FORMAT_NAME:
        raise ctx.error("format", f"expected {FORMAT_NAME!r}, got {data['format']!r}")
    if isinstance(data["version"], bool) or data["version"] != FORMAT_VERSION:  # `version: true` is not 1
        raise ctx.error("version", f"unsupported version {data['version']!r}; this openfdk reads {FORMAT_VERSION}")
    landmarks = _landmarks(ctx, data["landmarks"])
    offset = ctx.length * ctx.number(data.get("cartilage_offset", 1.0 * 1e-3 / length), "cartilage_offset", low=0.0)
    muscles = _muscles(ctx, data["muscles"], data.get("muscle_defaults"))
    protocol = parse_protocol(ctx, data, directory, landmarks, [m.name for m in muscles])
    return Subject(
        directory=directory, name=str(data.get("name", directory.name)),
        description=str(data.get("description", "")),
        landmarks=MappingProxyType(landmarks),
        tmj_planes=MappingProxyType(_planes(ctx, data["tmj_planes"])),
        mandible=_mandible(ctx, data["mandible"]),
        muscles=muscles,
        ligaments=_ligaments(ctx, data["ligaments"]),
        surfaces=MappingProxyType(_surfaces(ctx, data["surfaces"], directory, landmarks, length_unit)),
        braces=MappingProxyType(_braces(ctx, data["braces"])),
        cartilage_offset=offset, length_unit=length_unit, protocol=protocol)
