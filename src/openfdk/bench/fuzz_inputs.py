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
  replaced);
- ``osim``: an OpenSim model (three bodies, a PinJoint, a CustomJoint with a SimmSpline,
  a CoordinateCouplerConstraint, markers, a mesh) -> :func:`openfdk.io.modelfile.load_model`
  raises :class:`~openfdk.model.model.ModelError` (its subclass
  :class:`~openfdk.io.opensim.OsimError` for the reader's own checks);
- ``ik``: an OpenSim IK setup file with marker and coordinate tasks and its coordinate
  file, applied to that model (``--ik-tasks``) -> ``ModelError`` as well;
- ``external_loads``, ``grf_mot``, ``sto``, ``force_plates``, ``results``, ``checkpoint``
  and ``study_lock`` (issue 30), ``validation_map`` and ``validation_reference`` (``openfdk
  validate-kinematics``), ``checkpoint_fdk`` (an FDK run's parts, with its carried KKT
  factors): their bases, mutators and loaders are in
  :mod:`openfdk.bench.fuzz_kinds`.

Mutations of YAML files act on the parsed tree (a value replaced by one of another type
or magnitude, scaled by 1000 or 1/1000 as a unit mistake would, negated, a key deleted,
misspelt or added, a unit changed, a list shortened or lengthened) or on the text (cut
short, a line repeated — a duplicate key — or dropped, a byte changed). C3D mutations act
on the bytes (bytes changed, header and parameter words set to edge values, floats set
to NaN or huge, the file cut short or lengthened). OpenSim XML mutations act on the
element tree (a number replaced by NaN, inf, a huge, negative or malformed value, an
element deleted, duplicated, emptied or renamed, a name attribute changed to a duplicate
or a name with '/', '.' or '..') or on the text.
"""

from __future__ import annotations

import shutil
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import yaml

from .fuzz_kinds import NEW_KINDS

KINDS = ("model", "subject", "study", "c3d", "trc", "osim", "ik") + NEW_KINDS

_VALUES = (None, True, False, 0, -1, 1, 2, 5, 1.5, -2.5, 1e300, -1e300, 1e-300, float("nan"), float("inf"),
           "", "abc", "1e3", "m", "mm", "deg", [], {}, [1, 2], [0, 0, 0], [1, 2, 3, 4], [[1, 2, 3]], {"a": 1},
           "ground.origin", 10 ** 30, -(10 ** 30), "x" * 300)


# -- base inputs ----------------------------------------------------------------------

def base_model_dict():
    """A valid model file mapping exercising most sections: two bodies, a joint, markers,
    points, a measure, a driver-free FDK DOF, Hill and constant muscles, a ligament, a
    spring, a load, recruitment and FDK settings, a joint_reaction report (lengths in mm,
    angles in deg)."""
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
    d["joint_reaction"] = {"joint_names": ["tmj"], "apply_on_bodies": [{"side": "parent", "name": "skull"}],
                           "express_in_frame": [{"name": "jaw_frame", "body": "jaw", "position": [1.0, 2.0, 3.0],
                                                 "orientation": [10.0, 20.0, 30.0]}]}
    return d


_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def _dump(data):
    return yaml.dump(data, Dumper=_DUMPER, sort_keys=False, allow_unicode=True)


class Bases:
    """Valid base files of every kind in a temporary folder (removed by :meth:`close`)."""

    def __init__(self, kinds=KINDS):
        from . import fuzz_kinds

        self.dir = Path(tempfile.mkdtemp(prefix="openfdk-fuzz-"))
        self.texts, self.paths, self.originals = {}, {}, {}
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
        if {"osim", "ik", "external_loads", "grf_mot", "sto", "joint_reaction", "overlay"} & set(kinds):
            self.texts["osim"] = OSIM_TEXT
            self.paths["osim"] = write_leg(self.dir)
        if "ik" in kinds:
            self.texts["ik"] = IK_SETUP_TEXT
            self.paths["ik"] = self.dir / "Setup_IK.xml"
            self.paths["ik"].write_text(IK_SETUP_TEXT)
            (self.dir / "coords.mot").write_text("coords\nversion=1\nnRows=3\nnColumns=3\ninDegrees=yes\nendheader\n"
                                                 "time\thip_q\tknee\n0\t1\t-30\n0.05\t2\t-29\n0.1\t3\t-28\n")
        fuzz_kinds.build(self, kinds)

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


def mutate_text(text, rng, sep="\t"):
    """A mutated copy of a text table (cells separated by ``sep``): 1–3 line/character
    mutations or a number replaced by an edge value (NaN in C runtimes' spellings, inf,
    huge, negative, text)."""
    for _ in range(int(rng.integers(1, 4))):
        cells = text.split(sep)
        if rng.random() < 0.4 and len(cells) > 1:
            i = int(rng.integers(len(cells)))
            cells[i] = str(rng.choice(["NaN", "inf", "-1", "0", "1e308", "abc", "", "1e-320", "mm", "m", "7",
                                       "-nan(ind)", "1.#QNAN", "nan(", "1.#NAN"]))  # C runtimes' NaN, and near misses
            text = sep.join(cells)
        else:
            text = _text_mutation(text, rng)
    return text


#: a valid OpenSim 4.x model (as OpenSim 4.6 writes it, display elements left out): a
#: PinJoint hip, a CustomJoint knee with a SimmSpline translation, a patella coupled to the
#: knee, six markers and a mesh (Geometry/thigh.obj)
OSIM_TEXT = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40600">
 <Model name="leg">
  <Ground name="ground"/>
  <BodySet name="bodyset"><objects>
   <Body name="thigh">
    <attached_geometry><Mesh name="thigh_geom_1"><mesh_file>thigh.obj</mesh_file></Mesh></attached_geometry>
    <mass>5</mass><mass_center>0.01 -0.2 0</mass_center><inertia>0.1 0.02 0.1 0.001 0.002 0.003</inertia>
   </Body>
   <Body name="shank"><mass>3</mass><mass_center>0 -0.18 0.01</mass_center><inertia>0.05 0.01 0.05 0 0 0</inertia></Body>
   <Body name="patella"><mass>0.1</mass><mass_center>0 0 0</mass_center><inertia>0.001 0.001 0.001 0 0 0</inertia></Body>
  </objects></BodySet>
  <JointSet name="jointset"><objects>
   <PinJoint name="hip">
    <socket_parent_frame>ground_offset</socket_parent_frame>
    <socket_child_frame>thigh_offset</socket_child_frame>
    <coordinates><Coordinate name="hip_q"><range>-2 2</range></Coordinate></coordinates>
    <frames>
     <PhysicalOffsetFrame name="ground_offset"><socket_parent>/ground</socket_parent>
      <translation>0 1 0</translation><orientation>0.1 0.2 0.3</orientation></PhysicalOffsetFrame>
     <PhysicalOffsetFrame name="thigh_offset"><socket_parent>/bodyset/thigh</socket_parent>
      <translation>0 0.05 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>
    </frames>
   </PinJoint>
   <CustomJoint name="knee_j">
    <socket_parent_frame>thigh_offset</socket_parent_frame>
    <socket_child_frame>shank_offset</socket_child_frame>
    <coordinates><Coordinate name="knee"><default_value>-0.5</default_value></Coordinate></coordinates>
    <frames>
     <PhysicalOffsetFrame name="thigh_offset"><socket_parent>/bodyset/thigh</socket_parent>
      <translation>0 -0.4 0</translation><orientation>0 0 0.1</orientation></PhysicalOffsetFrame>
     <PhysicalOffsetFrame name="shank_offset"><socket_parent>/bodyset/shank</socket_parent>
      <translation>0 0.02 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>
    </frames>
    <SpatialTransform>
     <TransformAxis name="rotation1"><coordinates>knee</coordinates><axis>0 0 1</axis>
      <LinearFunction name="function"><coefficients>1 0</coefficients></LinearFunction></TransformAxis>
     <TransformAxis name="rotation2"><coordinates/><axis>1 0 0</axis></TransformAxis>
     <TransformAxis name="rotation3"><coordinates/><axis>0 1 0</axis></TransformAxis>
     <TransformAxis name="translation1"><coordinates>knee</coordinates><axis>1 0 0</axis>
      <SimmSpline name="function"><x>-2 -1.58333 -1.16667 -0.75 -0.333333 0.0833333 0.5</x>
       <y>-0.00909297 -0.00999921 -0.00919445 -0.00681639 -0.00327195 0.000832369 0.00479426</y></SimmSpline>
     </TransformAxis>
     <TransformAxis name="translation2"><coordinates/><axis>0 1 0</axis></TransformAxis>
     <TransformAxis name="translation3"><coordinates/><axis>0 0 1</axis></TransformAxis>
    </SpatialTransform>
   </CustomJoint>
   <PinJoint name="pat_j">
    <socket_parent_frame>shank_offset</socket_parent_frame>
    <socket_child_frame>patella_offset</socket_child_frame>
    <coordinates><Coordinate name="pat_q"/></coordinates>
    <frames>
     <PhysicalOffsetFrame name="shank_offset"><socket_parent>/bodyset/shank</socket_parent>
      <translation>0.05 0 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>
     <PhysicalOffsetFrame name="patella_offset"><socket_parent>/bodyset/patella</socket_parent>
      <translation>0 0 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>
    </frames>
   </PinJoint>
  </objects></JointSet>
  <ConstraintSet name="constraintset"><objects>
   <CoordinateCouplerConstraint name="pat_cc">
    <coupled_coordinates_function><LinearFunction><coefficients>0.5 0.1</coefficients></LinearFunction>
    </coupled_coordinates_function>
    <independent_coordinate_names>knee</independent_coordinate_names>
    <dependent_coordinate_name>pat_q</dependent_coordinate_name>
   </CoordinateCouplerConstraint>
  </objects></ConstraintSet>
  <MarkerSet name="markerset"><objects>
   <Marker name="T1"><socket_parent_frame>/bodyset/thigh</socket_parent_frame><location>0.05 -0.1 0.02</location></Marker>
   <Marker name="T2"><socket_parent_frame>/bodyset/thigh</socket_parent_frame><location>-0.04 -0.25 0.03</location></Marker>
   <Marker name="T3"><socket_parent_frame>/bodyset/thigh</socket_parent_frame><location>0.02 -0.3 -0.05</location></Marker>
   <Marker name="R.S1"><socket_parent_frame>/bodyset/shank</socket_parent_frame><location>0.03 -0.2 0.05</location></Marker>
   <Marker name="S2"><socket_parent_frame>/bodyset/shank</socket_parent_frame><location>-0.03 -0.3 0.04</location></Marker>
   <Marker name="S3"><socket_parent_frame>/bodyset/shank</socket_parent_frame><location>0.02 -0.1 -0.05</location></Marker>
  </objects></MarkerSet>
 </Model>
</OpenSimDocument>
"""


def write_leg(folder):
    """Write the leg model (:data:`OSIM_TEXT`) as ``folder/leg.osim`` with its mesh
    ``Geometry/thigh.obj`` (a tetrahedron); returns the .osim's path."""
    folder = Path(folder)
    (folder / "leg.osim").write_text(OSIM_TEXT)
    (folder / "Geometry").mkdir(exist_ok=True)
    (folder / "Geometry" / "thigh.obj").write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\n"
                                                   "f 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    return folder / "leg.osim"

#: an OpenSim IK setup for :data:`OSIM_TEXT`: marker weights and coordinate tasks of all
#: three value types (``from_file``: coords.mot beside it, in degrees)
IK_SETUP_TEXT = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
 <InverseKinematicsTool name="ik">
  <coordinate_file>coords.mot</coordinate_file>
  <IKTaskSet name="tasks"><objects>
   <IKMarkerTask name="T1"><apply>true</apply><weight>1</weight></IKMarkerTask>
   <IKMarkerTask name="T2"><apply>true</apply><weight>2</weight></IKMarkerTask>
   <IKMarkerTask name="T3"><apply>true</apply><weight>1</weight></IKMarkerTask>
   <IKMarkerTask name="R.S1"><apply>true</apply><weight>1</weight></IKMarkerTask>
   <IKMarkerTask name="S2"><apply>false</apply><weight>1</weight></IKMarkerTask>
   <IKCoordinateTask name="knee"><apply>true</apply><weight>0.1</weight><value_type>from_file</value_type></IKCoordinateTask>
   <IKCoordinateTask name="hip_q"><apply>true</apply><weight>0.1</weight><value_type>manual_value</value_type>
    <value>0.1</value></IKCoordinateTask>
   <IKCoordinateTask name="pat_q"><apply>true</apply><weight>1</weight><value_type>default_value</value_type>
   </IKCoordinateTask>
  </objects></IKTaskSet>
 </InverseKinematicsTool>
</OpenSimDocument>
"""

_XML_VALUES = ("NaN", "inf", "-inf", "1e308", "-1e308", "1e-320", "-1", "0", "", "abc", "0x10", "1_0", "1e999",
               "true", "maybe", " ", "/ground", "..", "ground", "knee", "hip_q", "T1")
_XML_TAGS = ("Body", "PinJoint", "WeldJoint", "Marker", "Constant", "SimmSpline", "Foo", "PhysicalOffsetFrame",
             "MultiplierFunction", "IKMarkerTask")


def mutate_xml(text, rng, n_mutations=None, values=_XML_VALUES, tags=_XML_TAGS):
    """A mutated copy of XML ``text``: 1–3 mutations of the element tree (a number or a
    text replaced by an edge value from ``values``, an element deleted, duplicated,
    emptied or renamed to one of ``tags``, a name attribute changed) or of the text (as
    for YAML files)."""
    from lxml import etree

    for _ in range(int(rng.integers(1, 4)) if n_mutations is None else n_mutations):
        try:
            root = etree.fromstring(text.encode(), etree.XMLParser(resolve_entities=False, no_network=True))
        except etree.XMLSyntaxError:
            root = None
        elements = [] if root is None else [e for e in root.iter() if isinstance(e.tag, str)][1:]
        if not elements or rng.random() < 0.15:
            text = _text_mutation(text, rng)
            continue
        e = elements[int(rng.integers(len(elements)))]
        op = int(rng.integers(7))
        if op == 0 and (e.text or "").strip():                     # one number or the whole text replaced
            tokens = e.text.split()
            tokens[int(rng.integers(len(tokens)))] = str(rng.choice(values))
            e.text = " ".join(tokens) if rng.random() < 0.7 else str(rng.choice(values))
        elif op == 1 and e.getparent() is not None:
            e.getparent().remove(e)
        elif op == 2 and e.getparent() is not None:                # duplicated: a second element, same name
            e.addnext(etree.fromstring(etree.tostring(e)))
        elif op == 3:
            for c in list(e):
                e.remove(c)
            e.text = None
        elif op == 4:
            e.tag = str(rng.choice(tags))
        elif op == 5 and e.get("name") is not None:
            e.set("name", str(rng.choice(["thigh", "shank", "hip", "knee", "knee_j", "T1", "a/b", "..", "R_S1",
                                          "ground", "x" * 300, ""])))
        else:
            e.text = str(rng.choice(values))
        text = etree.tostring(root, encoding="unicode")
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
    if kind in NEW_KINDS:
        from .fuzz_kinds import documented_error as new_kind_error

        return new_kind_error(kind)
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
    if kind in ("osim", "ik"):
        from ..model.model import ModelError

        return ModelError
    from ..io.c3d import C3DError

    return C3DError


def _load(kind, path, reader=None):
    if kind in NEW_KINDS:
        from .fuzz_kinds import load

        return load(kind, path, reader)
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
    if kind in ("osim", "ik"):
        from ..io.modelfile import load_model
        from ..io.opensim.overlay import register

        model = path.parent / "leg.osim"
        register(model, ik_tasks=path if kind == "ik" else None)
        return load_model(model)
    from ..io.c3d import read_c3d

    return read_c3d(path)


def fuzz(kind, n, seed=0, bases=None, time_limit=None):
    """Load ``n`` mutated inputs of ``kind``; returns a dict with counts ``inputs``,
    ``loaded``, ``refused`` (documented error naming the file) and ``unexpected``
    (a list of (seed, repr of the exception) for anything else), and ``seconds``."""
    from . import fuzz_kinds

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
            reader = None
            if kind in NEW_KINDS:
                reader = fuzz_kinds.mutate(kind, bases, rng)
            elif kind == "c3d":
                target.write_bytes(mutate_bytes(bases.c3d_bytes, rng))
            elif kind == "trc":
                target.write_text(mutate_text(bases.texts[kind], rng), encoding="utf-8")
            elif kind in ("osim", "ik"):
                target.write_text(mutate_xml(bases.texts[kind], rng), encoding="utf-8")
            else:
                target.write_text(mutate_yaml(bases.texts[kind], rng), encoding="utf-8")
            counts["inputs"] += 1
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    with np.errstate(all="ignore"):
                        _load(kind, target, reader)
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
        if kind in NEW_KINDS:
            fuzz_kinds.restore(kind, bases)
        elif original is not None:
            target.write_bytes(original)
        if own:
            bases.close()
    counts["seconds"] = time.perf_counter() - t0
    return counts


def reproduce(kind, seed, index, bases):
    """The mutated input number ``index`` of a :func:`fuzz` run with ``seed`` (for
    debugging an unexpected exception): str for YAML kinds, bytes for C3D; for the kinds
    of :mod:`.fuzz_kinds`, the input is left written over the base files and the result
    is {file name: bytes} of the files that differ from the base."""
    from . import fuzz_kinds

    rng = np.random.default_rng(seed)
    out = None
    if kind in NEW_KINDS:
        for _ in range(index + 1):
            fuzz_kinds.mutate(kind, bases, rng)
        return fuzz_kinds.current_input(kind, bases)
    for _ in range(index + 1):
        out = (mutate_bytes(bases.c3d_bytes, rng) if kind == "c3d" else mutate_text(bases.texts[kind], rng)
               if kind == "trc" else mutate_xml(bases.texts[kind], rng) if kind in ("osim", "ik")
               else mutate_yaml(bases.texts[kind], rng))
    return out


def main(argv=None):
    """``python -m openfdk.bench.fuzz_inputs [N] [SEED] [KIND ...]``: the long fuzz run;
    prints one line of counts per kind and exits 1 on any unexpected exception."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m openfdk.bench.fuzz_inputs",
                                     description="Mutate valid input files and read each mutant as openfdk "
                                                 "would: every one must load or be refused with its kind's "
                                                 "documented error (docs/input-checks.md).")
    parser.add_argument("n", nargs="?", type=int, default=10_000, help="mutated inputs per kind (default 10000)")
    parser.add_argument("seed", nargs="?", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("kinds", nargs="*", metavar="KIND", help=f"kinds to fuzz (default all: {' '.join(KINDS)})")
    args = parser.parse_args(argv)
    unknown = [k for k in args.kinds if k not in KINDS]
    if unknown:
        parser.error(f"unknown kind(s) {', '.join(unknown)} (kinds: {' '.join(KINDS)})")
    n, seed, kinds = args.n, args.seed, args.kinds or list(KINDS)
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


