"""``openfdk check`` tells the truth: inventory, rows against coordinates, redundant and
free rows found by rank at the reference pose, exit code 2 when the model cannot run."""

import pytest

from openfdk.cli import main

KNEE = """
units: {length: mm, angle: deg}
gravity: [0, 0, 0]
bodies:
  shank: {mass: 1.0, inertia: [0.01, 0.01, 0.002], position: [0, -200, 0], frames: {knee: [0, 200, 0]}}
{joints}
drivers:
  flexion: {measure: knee.angle, function: {type: constant, value: 20}}
{extra}
springs:
  kx: {measure: knee.position, component: 0, stiffness: 2000}
  ky: {measure: knee.position, component: 1, stiffness: 2000}
"""


def _write(tmp_path, joints, extra=""):
    f = tmp_path / "knee.yaml"
    f.write_text(KNEE.replace("{joints}", joints).replace("{extra}", extra))
    return f


def test_redundant_knee_exits_2_naming_the_rows(tmp_path, capsys):
    """The issue's knee: a revolute joint *and* FDK DOFs on its two translations."""
    f = _write(tmp_path, "joints:\n  knee: {type: revolute, parent: ground.origin, child: shank.knee}",
               "fdk_dofs:\n  knee_x: {measure: knee.position, component: 0}\n"
               "  knee_y: {measure: knee.position, component: 1}")
    assert main(["check", str(f)]) == 2
    out = capsys.readouterr()
    err = out.err.strip().splitlines()
    assert len(err) == 1
    assert "knee.yaml" in err[0] and "rank 6 of 8 rows" in err[0]
    for row in ("knee.x", "knee.y", "fdk.knee_x", "fdk.knee_y"):
        assert repr(row) in err[0]
    assert "knee.z" not in err[0]
    assert "rows: 5 joint/constraint + 1 driver + 2 FDK = 8; coordinates: 6" in out.out


def test_free_coordinate_exits_2_naming_it(tmp_path, capsys):
    """A spherical joint and one driven angle: two rotations are free, no markers."""
    f = tmp_path / "free.yaml"
    f.write_text("""
bodies:
  arm: {mass: 1.0, inertia: [1, 1, 1], frames: {pivot: [0, 0, 0.1]}}
joints:
  shoulder: {type: spherical, parent: ground.origin, child: arm.pivot}
drivers:
  abduction: {measure: shoulder.angles, components: [0], function: {type: constant, value: 0.1}}
""")
    assert main(["check", str(f)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "free.yaml" in err[0] and "2 coordinate(s) free" in err[0]
    assert "arm.ry" in err[0] and "arm.rz" in err[0] and "arm.rx" not in err[0]


def test_knee_with_fdk_rows_passes_and_lists_everything(tmp_path, capsys):
    f = _write(tmp_path, "joints:\n  knee: {type: revolute, parent: ground.origin, child: shank.knee, fdk: [x, y]}",
               "loads:\n  push: {point: shank.knee, force: [30, -12, 0]}")
    assert main(["check", str(f)]) == 0
    out = capsys.readouterr().out
    assert "joints: knee (revolute, 3 rows)" in out
    assert "FDK DOFs: knee_x, knee_y" in out
    assert "springs: 2 (kx, ky)" in out and "loads: 1 (push)" in out and "muscles: 0" in out
    assert "rank of the constraint Jacobian at the reference pose: 6 of 6 rows" in out
    assert "determinate" in out


def test_path_inside_a_wrapping_surface_is_listed(tmp_path, capsys):
    f = tmp_path / "wrap.yaml"
    f.write_text("""
units: {length: mm, angle: deg}
bodies:
  arm: {mass: 1.0, inertia: [0.01, 0.01, 0.01], position: [0, -200, 0], frames: {pivot: [0, 200, 0], insertion: [10, 150, 0]}}
  ground: {frames: {origin_point: [5, 5, 0]}}
joints:
  pin: {type: revolute, parent: ground.origin, child: arm.pivot}
drivers:
  swing: {measure: pin.angle, function: {type: constant, value: 0}}
wrapping:
  drum: {type: cylinder, frame: ground.origin, radius: 30}
muscles:
  m: {path: [ground.origin_point, drum, arm.insertion], strength: 100}
""")
    assert main(["check", str(f)]) == 0
    out = capsys.readouterr().out
    assert "muscles: 1 (m over drum)" in out
    assert "warning: muscle 'm' at the reference pose: path 'm': a path point lies inside the wrapping surface" in out


def test_free_osim_coordinates_are_named_by_their_coordinates(tmp_path, capsys):
    """An OpenSim model whose toe markers are gone (Gait2392's markers have none on the
    toes): the message names the coordinate the markers leave free, mtp_angle_r, and the
    overlay line that holds it; with that overlay the check passes."""
    import xml.etree.ElementTree as ET

    from openfdk.fixtures.full_body_osim import write_full_body_osim

    path = write_full_body_osim(tmp_path / "body.osim")
    tree = ET.parse(path)
    for markerset in tree.iter("MarkerSet"):
        objects = markerset.find("objects")
        for m in list(objects):
            if m.findtext("socket_parent_frame", "").endswith("toes_r"):
                objects.remove(m)
    tree.write(path)
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "body.osim" in err[0]
    assert "['mtp_angle_r']" in err[0] and "'lock: [mtp_angle_r]'" in err[0]
    assert "toes_r.rz" not in err[0]
    (tmp_path / "lock.yaml").write_text("lock: [mtp_angle_r]\n")
    assert main(["check", str(path), "--with", str(tmp_path / "lock.yaml")]) == 0, capsys.readouterr().err
