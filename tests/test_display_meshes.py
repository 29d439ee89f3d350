"""Display meshes (model-file ``visual:`` entries): the VTK XML PolyData (.vtp) and
Wavefront OBJ readers against files written here from a known closed mesh, the one
dispatching reader, malformed files (one ValueError line naming the file, quickly), and
the ``scale`` key through a model file into the viewer's scene and the OpenSim export,
against a hand computation of v_B = R_BF (S u v_file) + p_BF."""

import base64
import textwrap
import time
import zlib

import numpy as np
import pytest

from openfdk.io.meshfiles import DISPLAY_MESH_SUFFIXES, read_display_mesh
from openfdk.io.modelfile import load_model
from openfdk.io.obj import read_obj
from openfdk.io.polygons import fan_triangles, strip_triangles
from openfdk.io.vtp import read_vtp
from openfdk.model.visuals import visual_mesh_B

# A closed square pyramid: base quad (normal −z, outward) and four side triangles. The
# coordinates are exact in float32, so every format must give them back exactly.
PYRAMID_V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, 1.25]])
PYRAMID_POLYS = [[0, 3, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]
# the quad fan-triangulated from its first corner, then the triangles, in file order
PYRAMID_T = np.array([[0, 3, 2], [0, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])

_NP = {"Float32": "f4", "Float64": "f8", "Int32": "i4", "Int64": "i8", "UInt32": "u4", "UInt64": "u8"}


# -- writers (VTK's XML format as documented, written independently of the reader) ----------
def _binary(values, vtype, order, header, compress, block=16, one_stream=False):
    """base64 text of a binary DataArray: header and data encoded separately (VTK's way)
    or, with one_stream, as one base64 text."""
    bo = "<" if order == "LittleEndian" else ">"
    data = np.asarray(values).astype(bo + _NP[vtype]).tobytes()
    hd = bo + _NP[header]
    if not compress:
        head = np.array([len(data)], hd).tobytes()
        if one_stream:
            return base64.b64encode(head + data).decode()
        return base64.b64encode(head).decode() + base64.b64encode(data).decode()
    blocks = [data[i:i + block] for i in range(0, len(data), block)]
    packed = [zlib.compress(b) for b in blocks]
    last = len(blocks[-1]) if blocks and len(blocks[-1]) != block else 0
    head = np.array([len(blocks), block, last, *map(len, packed)], hd).tobytes()
    return base64.b64encode(head).decode() + base64.b64encode(b"".join(packed)).decode()


def _data_array(values, vtype, fmt, name="", components=1, enc=None, info=""):
    attrs = f'type="{vtype}"' + (f' Name="{name}"' if name else "") + \
        f' NumberOfComponents="{components}" format="{fmt}"'
    if fmt == "ascii":
        body = " ".join(repr(float(x)) if vtype.startswith("Float") else str(int(x)) for x in np.ravel(values))
    else:
        body = _binary(np.ravel(values), vtype, **enc)
    return f"<DataArray {attrs}>{info}\n{body}\n</DataArray>"


def vtp_text(vertices, polys, fmt="ascii", ftype="Float32", itype="Int32", order="LittleEndian",
             header="UInt32", compress=False, one_stream=False, normals=True, info=""):
    conn = [i for p in polys for i in p]
    offsets = np.cumsum([len(p) for p in polys])
    enc = {"order": order, "header": header, "compress": compress, "one_stream": one_stream}
    comp = ' compressor="vtkZLibDataCompressor"' if compress else ""
    point_data = ""
    if normals:
        n = vertices - vertices.mean(0)
        n = n / np.linalg.norm(n, axis=1)[:, None]
        point_data = f'<PointData Normals="Normals">{_data_array(n, "Float32", fmt, "Normals", 3, enc)}</PointData>'
    return "\n".join([
        '<?xml version="1.0"?>',
        f'<VTKFile type="PolyData" version="0.1" byte_order="{order}" header_type="{header}"{comp}>',
        "  <PolyData>",
        f'    <Piece NumberOfPoints="{len(vertices)}" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" '
        f'NumberOfPolys="{len(polys)}">',
        f"      {point_data}",
        f"      <Points>{_data_array(vertices, ftype, fmt, 'Points', 3, enc, info)}</Points>",
        "      <Polys>",
        f"        {_data_array(conn, itype, fmt, 'connectivity', 1, enc)}",
        f"        {_data_array(offsets, itype, fmt, 'offsets', 1, enc)}",
        "      </Polys>",
        "    </Piece>",
        "  </PolyData>",
        "</VTKFile>", ""])


def obj_text():
    """The pyramid as OBJ: comments, vt/vn lines, all corner forms, negative indices."""
    return textwrap.dedent("""\
        # pyramid
        mtllib bone.mtl
        o pyramid
        v 0 0 0
        v 1.0 0 0 1.0
        v 1 1 0
        v 0 1.0 0
        v 0.5 0.5 1.25 0.8 0.7 0.6
        vt 0 0
        vn 0 0 -1
        usemtl bone
        s off
        f 1/1/1 4/1/1 3/1/1 2/1/1   # the base quad
        f 1//1 2//1 5//1
        f 2/1 3/1 5/1
        f -3 -2 -1
        f 4 \\
          1 5
        l 1 2
        """)


# -- VTP ------------------------------------------------------------------------------------
VTP_CASES = {
    "ascii-float32": {},
    "ascii-float64-int64": {"ftype": "Float64", "itype": "Int64"},
    "ascii-with-information-key": {
        "info": '<InformationKey name="L2_NORM_RANGE" location="vtkDataArray" length="2">'
                '<Value index="0">0</Value><Value index="1">1.5</Value></InformationKey>'},
    "binary-float32-int32": {"fmt": "binary"},
    "binary-one-base64-stream": {"fmt": "binary", "one_stream": True},
    "binary-float64-int64-uint64-header": {"fmt": "binary", "ftype": "Float64", "itype": "Int64", "header": "UInt64"},
    "binary-big-endian": {"fmt": "binary", "order": "BigEndian", "ftype": "Float64"},
    "binary-zlib-float32": {"fmt": "binary", "compress": True},
    "binary-zlib-float64-int64-uint64-header": {"fmt": "binary", "compress": True, "ftype": "Float64",
                                                "itype": "Int64", "header": "UInt64"},
    "binary-uint32-indices": {"fmt": "binary", "itype": "UInt32", "normals": False},
}


@pytest.mark.parametrize("case", list(VTP_CASES))
def test_vtp_reads_the_written_mesh_exactly(tmp_path, case):
    path = tmp_path / f"{case}.vtp"
    path.write_text(vtp_text(PYRAMID_V, PYRAMID_POLYS, **VTP_CASES[case]))
    v, t = read_vtp(path)
    assert v.dtype == np.float64 and v.shape == (5, 3) and t.dtype == np.int64 and t.shape == (6, 3)
    np.testing.assert_array_equal(v, PYRAMID_V)
    np.testing.assert_array_equal(t, PYRAMID_T)
    v2, t2 = read_display_mesh(path)   # the dispatcher gives the same
    np.testing.assert_array_equal(v2, v)
    np.testing.assert_array_equal(t2, t)


def test_vtp_closed_mesh_has_outward_volume(tmp_path):
    """The fan triangulation keeps the winding: the pyramid's signed volume is +1.25/3."""
    path = tmp_path / "p.vtp"
    path.write_text(vtp_text(PYRAMID_V, PYRAMID_POLYS, fmt="binary", compress=True))
    v, t = read_vtp(path)
    vol = np.einsum("ij,ij->i", v[t[:, 0]], np.cross(v[t[:, 1]], v[t[:, 2]])).sum() / 6
    assert vol == pytest.approx(1.25 / 3, rel=1e-12)


def test_vtp_strips_and_several_pieces(tmp_path):
    strip = textwrap.dedent("""\
        <VTKFile type="PolyData" version="1.0" byte_order="LittleEndian">
          <PolyData>
            <Piece NumberOfPoints="3" NumberOfPolys="1">
              <Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 0 1 0</DataArray></Points>
              <Polys><DataArray type="Int32" Name="connectivity" format="ascii">0 1 2</DataArray>
                     <DataArray type="Int32" Name="offsets" format="ascii">3</DataArray></Polys>
            </Piece>
            <Piece NumberOfPoints="4" NumberOfStrips="1">
              <Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">0 0 1 1 0 1 0 1 1 1 1 1</DataArray></Points>
              <Strips><DataArray type="Int64" Name="connectivity" format="ascii">0 1 2 3</DataArray>
                      <DataArray type="Int64" Name="offsets" format="ascii">4</DataArray></Strips>
            </Piece>
          </PolyData>
        </VTKFile>
        """)
    path = tmp_path / "strip.vtp"
    path.write_text(strip)
    v, t = read_vtp(path)
    assert v.shape == (7, 3)
    np.testing.assert_array_equal(t, [[0, 1, 2], [3, 4, 5], [5, 4, 6]])


def test_polygon_helpers():
    np.testing.assert_array_equal(fan_triangles([7, 8, 9, 10, 11, 1, 2, 3], [5, 8]),
                                  [[7, 8, 9], [7, 9, 10], [7, 10, 11], [1, 2, 3]])
    np.testing.assert_array_equal(strip_triangles([0, 1, 2, 3, 4], [5]), [[0, 1, 2], [2, 1, 3], [2, 3, 4]])
    with pytest.raises(ValueError, match="not increasing"):
        fan_triangles([0, 1, 2, 3, 4, 5], [3, 3, 6])


# -- OBJ ------------------------------------------------------------------------------------
def test_obj_reads_the_written_mesh_exactly(tmp_path):
    path = tmp_path / "pyramid.obj"
    path.write_text(obj_text())
    v, t = read_obj(path)
    np.testing.assert_array_equal(v, PYRAMID_V)
    np.testing.assert_array_equal(t, PYRAMID_T)
    v2, t2 = read_display_mesh(tmp_path / "pyramid.obj")
    np.testing.assert_array_equal(v2, v)
    np.testing.assert_array_equal(t2, t)


def test_obj_written_by_the_opensim_exporter_reads_back(tmp_path):
    from openfdk.io.osim import _write_obj

    path = tmp_path / "g.obj"
    _write_obj(path, PYRAMID_V * 0.1, PYRAMID_T, "pyramid")
    v, t = read_display_mesh(path)
    np.testing.assert_array_equal(v, PYRAMID_V * 0.1)
    np.testing.assert_array_equal(t, PYRAMID_T)


# -- malformed files: one ValueError line naming the file -----------------------------------
def _good(**kw):
    return vtp_text(PYRAMID_V, PYRAMID_POLYS, **kw)


def _bomb():
    """Points declared as 5 × 3 Float32 (60 bytes); the one zlib block inflates to 20 MB."""
    packed = zlib.compress(bytes(20_000_000), 9)
    head = np.array([1, 60, 0, len(packed)], "<u4").tobytes()
    b64 = base64.b64encode(head).decode() + base64.b64encode(packed).decode()
    return _replace_points(b64, compress=True)


def _big_block_header():
    """A zlib header declaring 2 GB for an array the counts say holds 60 bytes."""
    packed = zlib.compress(bytes(60))
    head = np.array([1, 2**31, 0, len(packed)], "<u4").tobytes()
    return _replace_points(base64.b64encode(head).decode() + base64.b64encode(packed).decode(), compress=True)


def _replace_points(b64, compress):
    text = _good(fmt="binary", compress=compress, normals=False)
    start = text.index("<Points>")
    end = text.index("</Points>")
    return (text[:start] + '<Points><DataArray type="Float32" NumberOfComponents="3" format="binary">'
            + b64 + "</DataArray>" + text[end:])


def _corrupt_zlib():
    head = np.array([1, 60, 0, 12], "<u4").tobytes()
    return _replace_points(base64.b64encode(head).decode() + base64.b64encode(b"\x78\x9c" + bytes(10)).decode(), True)


def _truncated(text, cut):
    start = text.index('format="binary">', text.index("<Points>")) + len('format="binary">\n')
    end = text.index("\n</DataArray>", start)
    return text[:start] + text[start:end][:-cut] + text[end:]


LAUGHS = ('<?xml version="1.0"?>\n<!DOCTYPE VTKFile [<!ENTITY a "aaaaaaaaaa">'
          + "".join(f'<!ENTITY {chr(98 + i)} "' + f"&{chr(97 + i)};" * 10 + '">' for i in range(8))
          + ']>\n<VTKFile type="PolyData"><PolyData><Piece NumberOfPoints="1">'
          '<Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">&i;</DataArray></Points>'
          "</Piece></PolyData></VTKFile>")

VTP_BAD = {
    "empty": ("", "the file is empty"),
    "not-xml": ("solid stl\n", "not a well-formed XML"),
    "truncated-xml": (_good()[:400], "not a well-formed XML"),
    "entity-expansion": (LAUGHS, "entity"),   # libxml2 refuses the amplification while parsing
    "doctype": (_good().replace('<?xml version="1.0"?>', '<?xml version="1.0"?>\n<!DOCTYPE VTKFile [<!ENTITY n "4">]>'),
                "DOCTYPE"),
    "wrong-root": ('<VTKFile type="UnstructuredGrid"><UnstructuredGrid/></VTKFile>', "not 'PolyData'"),
    "no-piece": ('<VTKFile type="PolyData"><PolyData/></VTKFile>', "no <Piece>"),
    "base64-truncated": (_truncated(_good(fmt="binary"), 3), "not a multiple of 4"),
    "base64-truncated-at-group": (_truncated(_good(fmt="binary"), 8), "truncated"),
    "base64-garbage": (_replace_points("@@@@" * 20, False), "not base64"),
    "zlib-truncated": (_truncated(_good(fmt="binary", compress=True), 8), "truncated"),
    "zlib-corrupt": (_corrupt_zlib(), "zlib block 0"),
    "zlib-bomb": (_bomb(), "inflates to more than its declared 60 bytes"),
    "zlib-header-too-big": (_big_block_header(), "declared counts need 60"),
    "offsets-not-increasing": (_good().replace(">\n4 7 10 13 16\n<", ">\n4 7 7 13 16\n<"),
                               "offsets are not increasing (offset 2 is 7)"),
    "index-out-of-range": (_good().replace(">\n0 3 2 1 0 1 4", ">\n0 3 2 1 0 1 5"), "index 5 (entry 6) is out of range"),
    "nan-coordinate": (_good().replace(">\n0.0 0.0 0.0 1.0", ">\nnan 0.0 0.0 1.0"), "point 0 has a non-finite"),
    "too-few-points": (_good().replace('NumberOfPoints="5"', 'NumberOfPoints="6"'), "holds 15 values, expected 18"),
    "too-many-polys": (_good().replace('NumberOfPolys="5"', 'NumberOfPolys="4"'), "holds 5 values, expected 4"),
    "absurd-count": (_good().replace('NumberOfPoints="5"', 'NumberOfPoints="1000000000000"'), "out of range"),
    "count-not-a-number": (_good().replace('NumberOfPoints="5"', 'NumberOfPoints="five"'), "is not a count"),
    "two-corner-polygon": (_good().replace(">\n4 7 10 13 16\n<", ">\n4 6 10 13 16\n<"), "has 2 corner(s)"),
    "appended": (_good().replace('format="ascii"', 'format="appended" offset="0"'), "'appended'"),
    "lz4": (_good().replace('header_type="UInt32"', 'header_type="UInt32" compressor="vtkLZ4DataCompressor"'),
            "not supported"),
    "integer-points": (_good().replace('type="Float32" Name="Points"', 'type="Int32" Name="Points"'),
                       "type 'Int32' is not one of"),
    "text-index": (_good().replace(">\n0 3 2 1 0 1 4", ">\n0 3 2 x 0 1 4"), "not an integer"),
    "no-polys-element": (_good().replace("<Polys>", "<Lines>").replace("</Polys>", "</Lines>"), "no <Polys>"),
    "two-components": (_good().replace('Name="Points" NumberOfComponents="3"', 'Name="Points" NumberOfComponents="2"'),
                       "NumberOfComponents='2'"),
}


def test_malformed_cases_really_differ_from_the_good_file():
    good = _good()
    for name, (text, _) in VTP_BAD.items():
        assert text != good, name


@pytest.mark.parametrize("case", list(VTP_BAD))
def test_malformed_vtp_gives_one_line_naming_the_file(tmp_path, case):
    text, expected = VTP_BAD[case]
    path = tmp_path / f"{case}.vtp"
    path.write_text(text)
    t0 = time.perf_counter()
    with pytest.raises(ValueError) as err:
        read_display_mesh(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    assert expected in msg, msg
    assert time.perf_counter() - t0 < 5.0


def test_text_beyond_the_parser_limit_is_refused_in_one_line(tmp_path):
    """lxml without huge-tree mode stops at a text node of 10 MB: an ascii array that long
    is refused (quickly), with the remedy."""
    text = _good().replace(">\n0.0 0.0 0.0 1.0", ">\n" + "0 " * 5_100_000 + "0.0 0.0 0.0 1.0")
    path = tmp_path / "long.vtp"
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        read_vtp(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: ") and "more than 10 MB of text" in msg, msg


OBJ_BAD = {
    "index-out-of-range": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n", "line 5: face vertex index 4 is beyond the 3"),
    "index-zero": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "line 4: face corner '0'"),
    "negative-beyond": ("v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n", "line 3: face corner '-3' counts back"),
    "nan-vertex": ("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "line 2: vertex 2 has a non-finite"),
    "short-vertex": ("v 0 0\n", "line 1: a vertex needs x y z"),
    "text-vertex": ("v 0 zero 0\n", "line 1: vertex coordinates"),
    "two-corner-face": ("v 0 0 0\nv 1 0 0\nf 1 2\n", "line 3: a face needs at least 3 corners"),
    "bad-corner": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 a/2 3\n", "line 4: face corner 'a/2'"),
    "huge-index": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n", "line 4: face corner"),
    "binary": ("\0\1\2 not text", "binary file"),
    "no-faces": ("v 0 0 0\nv 1 0 0\n", "contains no triangles"),
}


@pytest.mark.parametrize("case", list(OBJ_BAD))
def test_malformed_obj_gives_one_line_naming_the_file(tmp_path, case):
    text, expected = OBJ_BAD[case]
    path = tmp_path / f"{case}.obj"
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        read_display_mesh(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    assert expected in msg, msg


@pytest.mark.parametrize("name, data, expected", [
    ("bone.xyz", b"", "unknown display-mesh format '.xyz'"),
    ("bone.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0\n", "ASCII STL"),
    ("bone.stl", b"\x01\x02" * 10, "neither a binary STL"),
    ("missing.vtp", None, "cannot read the file"),
])
def test_dispatcher_errors_name_the_file(tmp_path, name, data, expected):
    path = tmp_path / name
    if data is not None:
        path.write_bytes(data)
    with pytest.raises(ValueError) as err:
        read_display_mesh(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: ") and expected in msg, msg


def test_suffix_is_case_insensitive(tmp_path):
    assert ".vtp" in DISPLAY_MESH_SUFFIXES
    path = tmp_path / "BONE.VTP"
    path.write_text(_good())
    np.testing.assert_array_equal(read_display_mesh(path)[1], PYRAMID_T)


# -- scale and placement through a model file ------------------------------------------------
MODEL = """
openfdk: 1
units: {length: mm, angle: deg}
bodies:
  arm:
    mass: 1.0
    inertia: [0.01, 0.01, 0.01]
    position: [0, 0, -100]
    frames:
      pivot: [0, 0, 100]
    visual:
      mesh: meshes/pyramid.vtp
      units: cm
      scale: %s
      placement: {position: [10, 0, 0], orientation: [0, 0, 90]}
      color: "#e8dcc8"
joints:
  hinge: {type: revolute, parent: ground.origin, child: arm.pivot}
measures:
  arm_angles: {type: angles, frame: ground.origin, of: arm.origin}
drivers:
  swing:
    measure: arm_angles
    components: [2]
    function: {type: fourier, frequency: 1.0, a: [0, 30], b: [0]}
"""


def _model(tmp_path, scale="[2, -1, 0.5]"):
    (tmp_path / "meshes").mkdir(exist_ok=True)
    (tmp_path / "meshes" / "pyramid.vtp").write_text(_good(fmt="binary", compress=True))
    path = tmp_path / "model.yaml"
    path.write_text(MODEL % scale)
    return path


def _hand(scale):
    """v_B of the pyramid by hand: file cm -> m (0.01), S, Rz(90°): (x, y, z) -> (-y, x, z),
    then + (10 mm, 0, 0)."""
    s = 0.01 * np.asarray(scale) * PYRAMID_V
    return np.stack([-s[:, 1], s[:, 0], s[:, 2]], axis=1) + [0.010, 0.0, 0.0]


def test_scale_key_is_loaded_and_applied(tmp_path):
    model = load_model(_model(tmp_path))
    (vis,) = model.visuals
    np.testing.assert_array_equal(vis.scale, [2.0, -1.0, 0.5])
    v_B, t = visual_mesh_B(vis)
    np.testing.assert_allclose(v_B, _hand([2, -1, 0.5]), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(t, PYRAMID_T[:, ::-1])   # one negative factor: a mirror, winding reversed
    vol = np.einsum("ij,ij->i", v_B[t[:, 0]], np.cross(v_B[t[:, 1]], v_B[t[:, 2]])).sum() / 6
    assert vol > 0   # still outward
    (tmp_path / "unscaled.yaml").write_text((MODEL % "[1, 1, 1]").replace("      scale: [1, 1, 1]\n", ""))
    (vis1,) = load_model(tmp_path / "unscaled.yaml").visuals
    np.testing.assert_array_equal(vis1.scale, [1.0, 1.0, 1.0])
    v1, t1 = visual_mesh_B(vis1)
    np.testing.assert_allclose(v1, _hand([1, 1, 1]), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(t1, PYRAMID_T)


def test_viewer_scene_gets_the_scaled_vertices(tmp_path):
    from openfdk.viewer.pack import unpack
    from openfdk.viewer.scene import build_scene

    model = load_model(_model(tmp_path))
    scene = build_scene(model).data
    (mesh,) = [m for m in scene["meshes"] if m["kind"] == "visual"]
    assert mesh["body"] == model.body("arm").index and mesh["color"] == "#e8dcc8"
    v = unpack(mesh["vertices"]).reshape(-1, 3)
    np.testing.assert_allclose(v, _hand([2, -1, 0.5]), rtol=1e-7, atol=1e-9)   # packed as float32
    np.testing.assert_array_equal(unpack(mesh["faces"]).reshape(-1, 3), PYRAMID_T[:, ::-1])


def test_opensim_export_writes_the_scaled_mesh(tmp_path):
    from openfdk.io.osim import _geometry

    model = load_model(_model(tmp_path))
    attached = _geometry(model, tmp_path / "out")
    (entry,) = attached[model.body("arm").index]
    v, t = read_obj(tmp_path / "out" / entry[1])
    np.testing.assert_allclose(v, _hand([2, -1, 0.5]), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(t, PYRAMID_T[:, ::-1])


@pytest.mark.parametrize("scale, expected", [
    ("[1, 0, 1]", "bodies.arm.visual.scale: scale factors must be non-zero"),
    ("[1, 1]", "bodies.arm.visual.scale: expected 3 numbers"),
    ("[1, .nan, 1]", "bodies.arm.visual.scale: expected finite numbers"),
    ("2", "bodies.arm.visual.scale: expected 3 numbers"),
])
def test_bad_scale_is_named(tmp_path, scale, expected):
    with pytest.raises(ValueError, match=expected.replace(".", r"\.")):
        load_model(_model(tmp_path, scale))


def test_unknown_mesh_suffix_is_named_at_load(tmp_path):
    path = _model(tmp_path)
    (tmp_path / "meshes" / "pyramid.off").write_text("OFF\n")
    path.write_text(path.read_text().replace("pyramid.vtp", "pyramid.off"))
    with pytest.raises(ValueError, match=r"bodies\.arm\.visual\.mesh: unknown mesh format '\.off'"):
        load_model(path)


def test_unreadable_visual_mesh_is_a_view_error(tmp_path):
    from openfdk.viewer import ViewError
    from openfdk.viewer.scene import build_scene

    model = load_model(_model(tmp_path))
    (tmp_path / "meshes" / "pyramid.vtp").write_text(_good().replace('NumberOfPoints="5"', 'NumberOfPoints="6"'))
    with pytest.raises(ViewError) as err:
        build_scene(model)
    msg = str(err.value)
    assert "\n" not in msg and "bodies.arm.visual.mesh" in msg and "pyramid.vtp" in msg and "expected 18" in msg


@pytest.mark.parametrize("suffix", [".stl", ".vtp", ".obj"])
def test_an_empty_file_and_a_git_lfs_pointer_are_named_as_such(tmp_path, suffix):
    """A repository cloned without Git LFS (jam-resources stores its meshes there) leaves
    small text pointers where the meshes were, and a failed download leaves empty files:
    each is one line saying so, not a parse error of the format."""
    from openfdk.io.meshfiles import read_display_mesh

    empty, pointer = tmp_path / f"empty{suffix}", tmp_path / f"pointer{suffix}"
    empty.write_bytes(b"")
    pointer.write_text("version https://git-lfs.github.com/spec/v1\noid sha256:4d7a2146\nsize 1961899\n")
    with pytest.raises(ValueError) as info:
        read_display_mesh(empty)
    assert str(info.value) == f"{empty}: the file is empty"
    with pytest.raises(ValueError) as info:
        read_display_mesh(pointer)
    assert str(info.value) == (f"{pointer}: is a Git LFS pointer, not the file's content: its repository was cloned "
                               f"without its large files (run 'git lfs pull' there)")
