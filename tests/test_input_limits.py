"""Issue 30, item 3: inputs above the documented size limits (openfdk.io.limits) are
refused before the expensive work, with exit code 2 and one line naming the file, the
entry and the limit; an input at the limit is accepted. Large files are sparse (a header
and a truncate), so each test takes well under 2 s."""

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from cli_helpers import error_line, run_cli
from openfdk.fixtures.synthetic import two_body_model_dict
from openfdk.io import limits
from openfdk.io.meshfiles import read_display_mesh
from openfdk.io.yamlfile import parse_yaml, read_yaml
from openfdk.io.yamlgraph import check_graph

MODEL = yaml.safe_dump(two_body_model_dict(), sort_keys=False)


def _sparse(path, head: bytes, size: int):
    """A file of ``size`` bytes that begins with ``head`` (the rest a hole)."""
    with open(path, "wb") as f:
        f.write(head)
        f.truncate(size)
    return path


def _binary_stl(path, corners):
    """A binary STL with the triangles ``corners`` (m, 3, 3)."""
    corners = np.asarray(corners, dtype="<f4").reshape(-1, 3, 3)
    rec = np.zeros(len(corners), dtype=[("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    rec["corners"] = corners
    path.write_bytes(b"\0" * 80 + np.uint32(len(corners)).tobytes() + rec.tobytes())
    return path


def _fan(n):
    """n triangles of a fan around the origin (m, 3, 3)."""
    a = np.linspace(0, np.pi, n + 1)
    rim = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1) * 0.01
    return np.stack([np.zeros((n, 3)), rim[:-1], rim[1:]], axis=1)


# -- file bytes -------------------------------------------------------------------------

@pytest.mark.parametrize("command", ["check", "run"])
def test_a_model_file_above_the_byte_limit_is_refused(tmp_path, capsys, command):
    model = _sparse(tmp_path / "model.yaml", MODEL.encode(), limits.INPUT_FILE_BYTES + 1)
    extra = ["--out", tmp_path / "out"] if command == "run" else []
    code, _, err = run_cli(capsys, command, model, *extra)
    assert code == 2
    assert error_line(err) == ("openfdk: error: model.yaml: 67 108 865 bytes, above the limit of 67 108 864 bytes "
                               "(64 MiB) (openfdk.io.limits.INPUT_FILE_BYTES)")


def test_a_yaml_file_at_the_byte_limit_is_read(tmp_path, monkeypatch):
    path = tmp_path / "model.yaml"
    path.write_text(MODEL)
    monkeypatch.setattr(limits, "INPUT_FILE_BYTES", path.stat().st_size)
    assert read_yaml(path)["bodies"]
    monkeypatch.setattr(limits, "INPUT_FILE_BYTES", path.stat().st_size - 1)
    with pytest.raises(ValueError, match=r"model\.yaml: \d[\d ]* bytes, above the limit of .*INPUT_FILE_BYTES"):
        read_yaml(path)


def test_a_study_file_above_the_byte_limit_is_refused(tmp_path, capsys):
    study = _sparse(tmp_path / "s.yaml", b"openfdk_study: 1\n", limits.INPUT_FILE_BYTES + 1)
    code, _, err = run_cli(capsys, "study", study, "--out", tmp_path / "out")
    assert code == 2
    assert "s.yaml: 67 108 865 bytes, above the limit" in error_line(err)


def test_a_subject_file_above_the_byte_limit_is_refused(tmp_path):
    from openfdk.mandible.subject import SubjectError, load_subject

    (tmp_path / "subj").mkdir()
    _sparse(tmp_path / "subj" / "subject.yaml", b"units: {length: mm}\n", limits.INPUT_FILE_BYTES + 1)
    with pytest.raises(SubjectError, match=r"subject\.yaml: 67 108 865 bytes, above the limit .*INPUT_FILE_BYTES\)$"):
        load_subject(tmp_path / "subj")


@pytest.mark.parametrize("command", ["check", "run"])
def test_an_osim_file_above_the_byte_limit_is_refused(tmp_path, capsys, command):
    model = _sparse(tmp_path / "big.osim", b'<?xml version="1.0"?>\n<OpenSimDocument Version="40000">',
                    limits.INPUT_FILE_BYTES + 1)
    extra = ["--out", tmp_path / "out"] if command == "run" else []
    code, _, err = run_cli(capsys, command, model, *extra)
    assert code == 2
    assert "big.osim: 67 108 865 bytes, above the limit of 67 108 864 bytes (64 MiB) " \
           "(openfdk.io.limits.INPUT_FILE_BYTES)" in error_line(err)


# -- YAML aliases and expanded size -------------------------------------------------------

def _aliases(n):
    return "openfdk: 1\nbase: &b 1\nlst: [" + ", ".join(["*b"] * n) + "]\n"


def test_a_model_file_above_the_alias_limit_is_refused(tmp_path, capsys):
    model = tmp_path / "model.yaml"
    model.write_text(_aliases(limits.YAML_ALIASES + 1))
    code, _, err = run_cli(capsys, "check", model)
    assert code == 2
    assert error_line(err) == ("openfdk: error: model.yaml: line 3: 10 001 aliases (counted up to here), above the "
                               "limit of 10 000 (openfdk.io.limits.YAML_ALIASES)")


def test_a_yaml_file_at_the_alias_limit_is_read():
    assert len(parse_yaml(_aliases(limits.YAML_ALIASES), "a.yaml")["lst"]) == limits.YAML_ALIASES


def test_a_file_expanding_above_the_node_limit_is_refused(tmp_path, capsys):
    # a list of 9 999 items shared 1 000 times: 10 010 004 nodes, 1 000 aliases
    text = "big: &a [" + ", ".join(["0"] * 9_999) + "]\nuse: [" + ", ".join(["*a"] * 1000) + "]\n"
    model = tmp_path / "model.yaml"
    model.write_text(text)
    code, _, err = run_cli(capsys, "run", model, "--out", tmp_path / "out")
    assert code == 2
    assert error_line(err) == ("openfdk: error: model.yaml: 10 010 004 YAML nodes with the aliases expanded (most "
                               "under use), above the limit of 2 000 000 (openfdk.io.limits.YAML_NODES)")


def test_a_file_of_too_many_nodes_is_refused_before_it_is_composed(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(limits, "YAML_NODES", 1000)   # the real limit's file (4 MB) takes 2 s to scan
    model = tmp_path / "model.yaml"
    model.write_text("openfdk: 1\nx: [" + ", ".join(["1"] * 1000) + "]\n")   # 1 003 nodes
    monkeypatch.setattr("yaml.CSafeLoader.get_single_node", lambda self: pytest.fail("composed"), raising=False)
    code, _, err = run_cli(capsys, "check", model)
    assert code == 2
    assert error_line(err) == ("openfdk: error: model.yaml: line 2: 1 001 YAML nodes (counted up to here), above "
                               "the limit of 1 000 (openfdk.io.limits.YAML_NODES)")


def test_a_file_at_the_node_limit_is_read(monkeypatch):
    text = "x: [1, 2, 3]\n"                     # mapping, key, list, 3 items: 6 nodes
    monkeypatch.setattr(limits, "YAML_NODES", 6)
    assert parse_yaml(text, "t.yaml") == {"x": [1, 2, 3]}
    monkeypatch.setattr(limits, "YAML_NODES", 5)
    with pytest.raises(ValueError, match=r"^t\.yaml: line 1: 6 YAML nodes \(counted up to here\), above the limit of 5"):
        parse_yaml(text, "t.yaml")


def test_the_expanded_node_count_is_exact_and_the_limit_inclusive(monkeypatch):
    text = "a: &x [1, 2]\nb: [*x, *x]\n"   # mapping, 2 keys, a (3), b (1 + 2 × 3)
    node = yaml.compose(text, Loader=yaml.SafeLoader)
    assert check_graph(node, "t.yaml") == 1 + 2 + 3 + 7
    monkeypatch.setattr(limits, "YAML_NODES", 13)
    assert parse_yaml(text, "t.yaml") == {"a": [1, 2], "b": [[1, 2], [1, 2]]}
    monkeypatch.setattr(limits, "YAML_NODES", 12)
    with pytest.raises(ValueError, match=r"^t\.yaml: 13 YAML nodes with the aliases expanded \(most under b\), "
                                         r"above the limit of 12 \(openfdk\.io\.limits\.YAML_NODES\)$"):
        parse_yaml(text, "t.yaml")


def test_a_recursive_alias_is_refused(tmp_path, capsys):
    model = tmp_path / "model.yaml"
    model.write_text("openfdk: 1\na: &a [1, *a]\n")
    code, _, err = run_cli(capsys, "check", model)
    assert code == 2
    assert "model.yaml: a[1]: an alias refers to a node that contains it" in error_line(err)


# -- study cases ------------------------------------------------------------------------

def _study(tmp_path, grid):
    (tmp_path / "m.yaml").write_text(MODEL)
    data = {"openfdk_study": 1, "models": {"m": "m.yaml"},
            "parameters": {k: "bodies.jaw.mass" for k in grid}, "grid": grid}
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_study_above_the_case_limit_is_refused(tmp_path, capsys):
    study = _study(tmp_path, {"a": list(range(317)), "b": list(range(316))})
    code, _, err = run_cli(capsys, "study", study, "--out", tmp_path / "out")
    assert code == 2
    assert error_line(err) == ("openfdk: error: s.yaml: grid: 100 172 cases (1 input combination × (317 × 316 grid "
                               "points)), above the limit of 100 000 (openfdk.io.limits.STUDY_CASES)")


def test_a_study_at_the_case_limit_is_accepted(tmp_path, monkeypatch):
    from openfdk.study.spec import StudyError, load_study

    study = _study(tmp_path, {"a": [1.0, 2.0], "b": [1.0, 2.0]})
    monkeypatch.setattr(limits, "STUDY_CASES", 4)
    assert len(load_study(study, check_overrides=False).cases) == 4
    monkeypatch.setattr(limits, "STUDY_CASES", 3)
    with pytest.raises(StudyError, match=r"s\.yaml: grid: 4 cases .*above the limit of 3"):
        load_study(study, check_overrides=False)


def test_a_study_of_too_many_input_combinations_is_refused(tmp_path, monkeypatch):
    from openfdk.study.spec import StudyError, study_from_dict

    for name in ("a", "b"):
        (tmp_path / f"{name}.yaml").write_text(MODEL)
        (tmp_path / f"{name}.c3d").write_bytes(b"")
    data = {"openfdk_study": 1, "models": ["a.yaml", "b.yaml"], "trials": ["a.c3d", "b.c3d"]}
    monkeypatch.setattr(limits, "STUDY_CASES", 4)
    assert len(study_from_dict(data, "s.yaml", tmp_path, check_overrides=False).cases) == 4
    monkeypatch.setattr(limits, "STUDY_CASES", 3)
    with pytest.raises(StudyError, match=r"^s\.yaml: 4 cases \(4 input combinations\), above the limit of 3 "
                                         r"\(openfdk\.io\.limits\.STUDY_CASES\)$"):
        study_from_dict(data, "s.yaml", tmp_path, check_overrides=False)


# -- meshes -----------------------------------------------------------------------------

def test_a_binary_stl_above_the_triangle_limit_is_refused_from_its_header(tmp_path, capsys):
    n = limits.MESH_TRIANGLES + 1
    _sparse(tmp_path / "big.stl", b"\0" * 80 + np.uint32(n).tobytes(), 84 + 50 * n)   # 250 MB, a hole
    data = two_body_model_dict()
    data["contacts"] = {"c": {"vertices": {"body": "jaw", "mesh": "big.stl"},
                              "surface": {"body": "skull", "mesh": "big.stl"}, "pressure_modulus": 1e9}}
    model = tmp_path / "model.yaml"
    model.write_text(yaml.safe_dump(data))
    code, _, err = run_cli(capsys, "check", model)
    assert code == 2
    assert error_line(err) == ("openfdk: error: model.yaml: contacts.c.vertices.mesh: could not read mesh file "
                               f"'{tmp_path / 'big.stl'}': 5 000 001 triangles (binary STL header), above the limit "
                               "of 5 000 000 (openfdk.io.limits.MESH_TRIANGLES)")
    with pytest.raises(ValueError, match=r"big\.stl: 5 000 001 triangles .*MESH_TRIANGLES"):
        read_display_mesh(tmp_path / "big.stl")


def test_a_mesh_at_the_triangle_limit_is_read(tmp_path, monkeypatch):
    from openfdk.contact.mesh import MeshError, load_mesh

    stl = _binary_stl(tmp_path / "fan.stl", _fan(8))
    monkeypatch.setattr(limits, "MESH_TRIANGLES", 8)
    assert len(load_mesh(stl).faces) == 8
    assert len(read_display_mesh(stl)[1]) == 8
    monkeypatch.setattr(limits, "MESH_TRIANGLES", 7)
    with pytest.raises(MeshError, match=r"8 triangles \(binary STL header\), above the limit of 7"):
        load_mesh(stl)


def test_a_subject_mesh_above_the_triangle_limit_is_refused_from_its_header(tmp_path):
    from openfdk.mandible import SubjectError, create_subject, load_subject

    folder = create_subject(tmp_path / "virtual", resolution="coarse")
    n = limits.MESH_TRIANGLES + 1
    _sparse(folder / "fossa_l.stl", b"\0" * 80 + np.uint32(n).tobytes(), 84 + 50 * n)
    with pytest.raises(SubjectError, match=r"surfaces\.fossa_l: mesh file 'fossa_l\.stl': 5 000 001 triangles "
                                           r"\(binary STL header\), above the limit of 5 000 000 "
                                           r"\(openfdk\.io\.limits\.MESH_TRIANGLES\)$"):
        load_subject(folder)


@pytest.mark.parametrize("name, head", [("big.stl", b"solid big\n"), ("big.obj", b"v 0 0 0\n"),
                                        ("big.vtp", b"<VTKFile"), ("big.ply", b"ply\n")])
def test_a_mesh_file_above_the_byte_limit_is_refused_before_reading(tmp_path, name, head):
    path = _sparse(tmp_path / name, head, limits.MESH_FILE_BYTES + 1)
    with pytest.raises(ValueError, match=re.escape(f"{name}: 268 435 457 bytes") + r".*above the limit of "
                       r"268 435 456 bytes \(256 MiB\) \(openfdk\.io\.limits\.MESH_FILE_BYTES\)"):
        read_display_mesh(path)


def test_a_contact_mesh_of_another_format_above_the_byte_limit_is_refused(tmp_path):
    from openfdk.contact.mesh import MeshError, load_mesh

    path = _sparse(tmp_path / "big.ply", b"ply\n", limits.MESH_FILE_BYTES + 1)
    with pytest.raises(MeshError, match=r"big\.ply': 268 435 457 bytes, above the limit"):
        load_mesh(path)


def test_a_vtp_polygon_above_the_triangle_limit_is_refused_before_decoding(tmp_path):
    n = limits.MESH_TRIANGLES + 3   # one polygon of n corners: n - 2 triangles
    vtp = tmp_path / "big.vtp"
    vtp.write_text(f"""<VTKFile type="PolyData" version="0.1"><PolyData>
<Piece NumberOfPoints="3" NumberOfPolys="1">
<Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 0 1 0</DataArray></Points>
<Polys><DataArray type="Int32" Name="connectivity" format="ascii">0 1 2</DataArray>
<DataArray type="Int32" Name="offsets" format="ascii">{n}</DataArray></Polys>
</Piece></PolyData></VTKFile>""")
    with pytest.raises(ValueError, match=r"big\.vtp: <Polys>: 5 000 001 triangles, above the limit of 5 000 000 "
                                         r"\(openfdk\.io\.limits\.MESH_TRIANGLES\)$"):
        read_display_mesh(vtp)


def test_an_obj_mesh_above_the_triangle_limit_is_refused(tmp_path, monkeypatch):
    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    monkeypatch.setattr(limits, "MESH_TRIANGLES", 2)
    assert len(read_display_mesh(obj)[1]) == 2
    monkeypatch.setattr(limits, "MESH_TRIANGLES", 1)
    with pytest.raises(ValueError, match=r"quad\.obj: 2 triangles, above the limit of 1"):
        read_display_mesh(obj)


# -- documentation ----------------------------------------------------------------------

def test_every_limit_is_in_the_documented_table():
    text = (Path(__file__).parents[1] / "docs" / "input-checks.md").read_text()
    rows = {ln.split("|")[1].strip(" `"): ln for ln in text.splitlines() if ln.startswith("| `")}
    for name in (n for n in limits.__all__ if n.isupper()):
        assert name in rows, name
        value = getattr(limits, name)
        shown = f"{value // 2**20} MiB" if name.endswith("_BYTES") else (f"{value:,}".replace(",", " ")
                                                                          if isinstance(value, int) else f"{value:.0e}".replace("+0", ""))
        assert shown in rows[name], (name, shown, rows[name])
