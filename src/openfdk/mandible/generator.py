"""Generate a virtual mandible subject folder (docs/subject-folder.md).

:func:`create_subject` writes ``subject.yaml``, the four contact STL files and
``truth/anatomy.yaml`` (the analytic surfaces the STL files mesh, read back by the
virtual experiment; not part of the public folder format). The numbers come from
``openfdk/data/mandible/generic_subject.yaml`` and ``muscles.yaml``, whose comments name
their sources.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .geometry import RESOLUTIONS, CondyleShape, FossaShape, condyle_mesh, fossa_mesh
from .subject import FORMAT_NAME, FORMAT_VERSION, SUBJECT_FILE
from .truth import SIDES, TrueJoint, TruthOptions, min_gap

__all__ = [
    "ANATOMY_FILE",
    "VirtualAnatomy",
    "build_anatomy",
    "create_subject",
    "generic_data",
    "load_anatomy",
    "tmj_plane_normal",
]

DATA_DIR = Path(__file__).resolve().parent.parent / "data" / "mandible"
ANATOMY_FILE = Path("truth") / "anatomy.yaml"
#: display meshes of the bones (:mod:`.bone_meshes`; mm, subject frame, reference pose)
SKULL_MESH, MANDIBLE_MESH = "skull.stl", "mandible.stl"
_MM = 1e-3
_DEG = np.pi / 180.0
_MEDIAL_SIGN = {"r": 1.0, "l": -1.0}       # medial = +y on the right, −y on the left


def generic_data() -> tuple[dict, dict]:
    """The generic subject numbers and the muscle table (YAML data files, as written)."""
    subject = yaml.safe_load((DATA_DIR / "generic_subject.yaml").read_text(encoding="utf-8"))
    muscles = yaml.safe_load((DATA_DIR / "muscles.yaml").read_text(encoding="utf-8"))
    return subject, muscles


def _mirror(v, side: str) -> np.ndarray:
    """A right-side vector (…, 3) as given, or mirrored in y for the left side."""
    v = np.array(v, dtype=float)
    if side == "l":
        v[..., 1] *= -1.0
    return v + 0.0          # + 0.0 turns -0.0 into 0.0


def tmj_plane_normal(side: str, downward_anterior: float, medial_cant: float) -> np.ndarray:
    """Unit normal (3,) (pointing up) of the point-on-plane TMJ plane, angles in rad.

    The plane contains d₁ = (cos α, 0, −sin α) (down-anteriorly by α) and
    d₂ = (0, m cos β, −sin β) (down toward medial by β; m = +1 right, −1 left):
    n = d₁ × d₂ / |d₁ × d₂|, oriented so n_z > 0.
    """
    m = _MEDIAL_SIGN[side]
    d1 = np.array([np.cos(downward_anterior), 0.0, -np.sin(downward_anterior)])
    d2 = np.array([0.0, m * np.cos(medial_cant), -np.sin(medial_cant)])
    n = np.cross(d1, d2)
    n /= np.linalg.norm(n)
    return n if n[2] > 0 else -n


@dataclass(frozen=True)
class VirtualAnatomy:
    """The generated analytic TMJ surfaces (SI): ``condyles``/``fossae`` side → shape,
    ``layer`` m (the uniform cartilage offset used to seat the condyles)."""

    condyles: dict
    fossae: dict
    layer: float

    def to_dict(self) -> dict:
        out = {"units": "SI (m, rad)", "layer": self.layer, "condyles": {}, "fossae": {}}
        for side in SIDES:
            c = self.condyles[side]
            out["condyles"][side] = {"top": c.top.tolist(), "semi_axes": c.semi_axes.tolist(),
                                     "axis_angle": float(c.axis_angle), "cap_extent": float(c.cap_extent)}
            f = self.fossae[side]
            d = {k: getattr(f, k) for k in f.__dataclass_fields__ if not k.startswith("_")}
            d = {k: np.asarray(v, dtype=float).tolist() for k, v in d.items()}   # plain floats
            out["fossae"][side] = d
        return out

    @classmethod
    def from_dict(cls, d: dict) -> VirtualAnatomy:
        condyles = {s: CondyleShape(**d["condyles"][s]) for s in SIDES}
        fossae = {}
        for s in SIDES:
            f = dict(d["fossae"][s])
            f["extent_xi"], f["extent_eta"] = tuple(f["extent_xi"]), tuple(f["extent_eta"])
            fossae[s] = FossaShape(**f)
        return cls(condyles, fossae, float(d["layer"]))


def build_anatomy(symmetric: bool = True, seed: int = 0, asymmetry: float = 1.0) -> VirtualAnatomy:
    """The analytic condyles and fossae of the generic subject.

    ``symmetric=False`` perturbs each side's shape parameters by uniform random amounts
    within ``asymmetry`` × the bounds in the data file (seeded by ``seed``). Each fossa is
    then lowered/raised so that, in the reference pose, its condyle offset by the uniform
    cartilage layer touches it (min gap exactly 0).
    """
    data, _ = generic_data()
    rng = np.random.default_rng(seed)
    bounds = data["asymmetry"]
    scale = 0.0 if symmetric else float(asymmetry)

    def jitter(bound):
        return scale * bound * rng.uniform(-1.0, 1.0)

    half_width = 0.5 * data["intercondylar_distance"] * _MM
    dz = jitter(bounds["condyle_height_mm"]) * _MM
    cd, fd = data["condyle"], data["fossa"]
    layer = data["cartilage_offset"] * _MM
    condyles, fossae = {}, {}
    for side in SIDES:
        m = _MEDIAL_SIGN[side]
        top = np.array([0.0, -m * half_width, m * dz])      # origin stays midway
        size = 1.0 + jitter(bounds["condyle_size_fraction"])
        turn = jitter(bounds["long_axis_angle_deg"])
        angle = m * (cd["long_axis_angle"] + turn) * _DEG
        condyles[side] = CondyleShape(
            top=top, semi_axes=0.5 * _MM * size * np.array([cd["antero_posterior_depth"],
                                                            cd["medio_lateral_width"], 2.0 * cd["height"]]),
            axis_angle=angle, cap_extent=cd["cap_extent"])
        fossae[side] = FossaShape(
            top=top, axis_angle=m * (fd["axis_angle"] + turn) * _DEG, medial_sign=m, height_offset=layer,
            depth=(fd["depth"] + jitter(bounds["fossa_depth_mm"])) * _MM,
            eminence_slope=(fd["eminence_slope"] + jitter(bounds["eminence_slope_deg"])) * _DEG,
            eminence_start=fd["eminence_start"] * _MM, corner_width=fd["corner_width"] * _MM,
            posterior_wall_position=fd["posterior_wall"]["position"] * _MM,
            posterior_wall_slope=fd["posterior_wall"]["slope"],
            anterior_face_position=fd["anterior_face"]["position"] * _MM,
            anterior_face_slope=fd["anterior_face"]["slope"],
            medial_wall_position=fd["medial_wall"]["position"] * _MM,
            medial_wall_slope=fd["medial_wall"]["slope"],
            lateral_wall_position=fd["lateral_wall"]["position"] * _MM,
            lateral_wall_slope=fd["lateral_wall"]["slope"],
            extent_xi=tuple(_MM * np.asarray(fd["extent_xi"])),
            extent_eta=tuple(_MM * np.asarray(fd["extent_eta"])))
    # seat: the gap is Z − P_z and Z contains h_0 additively, so h_0 ← h_0 − min gap
    joint = TrueJoint.build(condyles, fossae, layer, TruthOptions.exact(), rng)
    identity, origin = np.eye(3)[None], np.zeros((1, 3))
    for side in SIDES:
        gap = min_gap(joint, side, identity, origin)[0][0]
        fossae[side] = fossae[side].with_height_offset(fossae[side].height_offset - gap)
    return VirtualAnatomy(condyles, fossae, layer)


def load_anatomy(directory: str | os.PathLike) -> VirtualAnatomy:
    """Read ``truth/anatomy.yaml`` written by :func:`create_subject`."""
    path = Path(directory) / ANATOMY_FILE
    if not path.is_file():
        raise ValueError(f"{path}: missing; the virtual experiment needs the analytic anatomy "
                         f"that create_subject writes (a folder of real data has no truth)")
    return VirtualAnatomy.from_dict(yaml.safe_load(path.read_text(encoding="utf-8")))


def _mm(v, digits: int = 6):
    """Metres → mm list/float, rounded to 1 nm."""
    a = np.round(np.asarray(v, dtype=float) / _MM, digits) + 0.0     # + 0.0: no "-0.0"
    return a.tolist() if a.ndim else float(a)


class _PlainDumper(yaml.SafeDumper):
    """Safe dumper without YAML anchors/aliases (repeated lists are written out)."""

    def ignore_aliases(self, data):
        return True


def _write_stl(path: Path, vertices_m: np.ndarray, faces: np.ndarray) -> None:
    import trimesh

    mesh = trimesh.Trimesh(vertices=vertices_m / _MM, faces=faces, process=False)
    path.write_bytes(mesh.export(file_type="stl"))


def _subject_document(anatomy: VirtualAnatomy, name: str) -> dict:
    data, muscle_table = generic_data()
    landmarks = {f"condyle_top_{s}": _mm(anatomy.condyles[s].top) for s in SIDES}
    landmarks["incisal_point"] = list(map(float, data["landmarks"]["incisal_point"]))
    for kind in ("molar", "premolar"):
        for s in SIDES:
            landmarks[f"{kind}_{s}"] = (_mirror(data["landmarks"][f"{kind}_r"], s) + 0.0).tolist()
    plane = data["tmj_plane"]
    planes = {s: {"point": landmarks[f"condyle_top_{s}"],
                  "normal": np.round(tmj_plane_normal(s, plane["downward_anterior"] * _DEG,
                                                      plane["medial_cant"] * _DEG), 12).tolist()}
              for s in SIDES}
    md = data["mandible"]
    mandible = {"mass": md["mass"], "center_of_mass": md["center_of_mass"],
                "inertia": np.diag(md["principal_inertia"]).tolist()}
    muscles = {}
    for s in SIDES:
        for mname, m in muscle_table["muscles"].items():
            entry = {"origin": _mirror(m["origin"], s).tolist(), "insertion": _mirror(m["insertion"], s).tolist()}
            entry.update({k: m[k] for k in ("max_isometric_force", "optimal_fibre_length", "tendon_slack_length")})
            entry.update(muscle_table["defaults"])
            muscles[f"{mname}_{s}"] = entry
    ligaments = {}
    for s in SIDES:
        top = anatomy.condyles[s].top / _MM
        for i, element in enumerate(data["tmj_ligament"], start=1):
            origin, insertion = top + _mirror(element["origin"], s), top + _mirror(element["insertion"], s)
            ligaments[f"tmj_ligament_{s}_{i}"] = {
                "origin": np.round(origin, 6).tolist(), "insertion": np.round(insertion, 6).tolist(),
                "reference_length": round(float(np.linalg.norm(insertion - origin)), 6)}
    surfaces = {f"{kind}_{s}": {"file": f"{kind}_{s}.stl", "units": "mm"}
                for kind in ("condyle", "fossa") for s in SIDES}
    b = data["braces"]
    corner = 0.5 * b["plate_size"] - b["marker_inset"]
    braces = {}
    for body in ("skull", "mandible"):
        centre = np.asarray(b[body]["plate_center"], dtype=float)
        markers = {}
        for code, (sy, sz) in {"RS": (-1, 1), "LS": (1, 1), "RI": (-1, -1), "LI": (1, -1)}.items():
            markers[f"{b[body]['prefix']}_{code}"] = (centre + [b["marker_standoff"], sy * corner, sz * corner]).tolist()
        braces[body] = {"markers": markers, "plate_size": b["plate_size"], "marker_diameter": b["marker_diameter"]}
    return {
        "format": FORMAT_NAME, "version": FORMAT_VERSION, "name": name,
        "description": "openfdk virtual mandible subject (generated; generic adult anatomy, "
                       "sources in openfdk/data/mandible/*.yaml)",
        "units": {"length": "mm", "angle": "deg"},
        "cartilage_offset": data["cartilage_offset"],
        "landmarks": landmarks, "tmj_planes": planes, "mandible": mandible,
        "muscles": muscles, "ligaments": ligaments, "surfaces": surfaces, "braces": braces,
    }


_HEADER = """\
# openfdk mandible subject folder (format: docs/subject-folder.md), generated by
# openfdk.mandible.create_subject. Frame: origin midway between the most superior points
# of the two condyles, x anterior, y left, z up (Frankfurt horizontal). All positions are
# in this frame at the reference (closed-mouth) pose, where the skull and mandible frames
# coincide. Lengths in `units.length`, angles in `units.angle`; mass kg, inertia kg m^2
# (about the centre of mass, subject axes), forces N. Muscles: de Zee et al. 2007,
# J Biomech 40:1192; origin on the skull, insertion on the mandible.
"""


def create_subject(directory: str | os.PathLike, *, resolution: str = "default",
                   symmetric: bool = True, seed: int = 0, asymmetry: float = 1.0,
                   name: str = "virtual-subject") -> Path:
    """Write a virtual subject folder and return its path.

    Args:
        directory: folder to create (or reuse: generated files are overwritten).
        resolution: mesh size, "coarse" (condyle ≈ 470 vertices, fossa ≈ 2 900 triangles),
            "default" (≈ 4 000 vertices, ≈ 9 800 triangles) or "fine".
        symmetric: False perturbs each side's shape (see :func:`build_anatomy`).
        seed: random seed of the asymmetry.
        asymmetry: scale of the asymmetric perturbation (× the data-file bounds).
        name: subject name written to subject.yaml.
    Writes: subject.yaml, condyle_r.stl, condyle_l.stl, fossa_r.stl, fossa_l.stl (binary
    STL, mm, subject frame at the reference pose), the display meshes skull.stl and
    mandible.stl (:mod:`.bone_meshes`, same frame and unit) and truth/anatomy.yaml.
    """
    if resolution not in RESOLUTIONS:
        raise ValueError(f"resolution {resolution!r}: expected one of {list(RESOLUTIONS)}")
    directory = Path(directory)
    (directory / ANATOMY_FILE).parent.mkdir(parents=True, exist_ok=True)
    anatomy = build_anatomy(symmetric=symmetric, seed=seed, asymmetry=asymmetry)
    sizes = RESOLUTIONS[resolution]
    for s in SIDES:
        _write_stl(directory / f"condyle_{s}.stl", *condyle_mesh(anatomy.condyles[s], sizes["condyle_rings"]))
        _write_stl(directory / f"fossa_{s}.stl", *fossa_mesh(anatomy.fossae[s], *sizes["fossa_grid"]))
    from .bone_meshes import mandible_mesh, skull_mesh

    incisal_point = np.asarray(generic_data()[0]["landmarks"]["incisal_point"], dtype=float) * _MM
    for file, make in ((MANDIBLE_MESH, mandible_mesh), (SKULL_MESH, skull_mesh)):
        _write_stl(directory / file, *make(anatomy.condyles, incisal_point))
    document = _subject_document(anatomy, name)
    text = _HEADER + yaml.dump(document, Dumper=_PlainDumper, sort_keys=False,
                                default_flow_style=None, width=100)
    (directory / SUBJECT_FILE).write_text(text, encoding="utf-8")
    record = anatomy.to_dict()
    record["generator"] = {"resolution": resolution, "symmetric": bool(symmetric), "seed": int(seed),
                           "asymmetry": float(asymmetry)}
    (directory / ANATOMY_FILE).write_text(
        "# Analytic TMJ surfaces of this virtual subject (SI units), read by the virtual\n"
        "# experiment (openfdk.mandible.experiment). Not part of the subject folder format.\n"
        + yaml.safe_dump(record, sort_keys=False), encoding="utf-8")
    return directory
