"""Write the STL meshes of the knee contact example (examples/knee/knee_contact.yaml).

    python examples/knee/make_meshes.py [OUTPUT_DIR]     (default: examples/knee/meshes)

Both surfaces are generated here from simple shapes (no third-party files), in mm, in
their body frames (x anterior, y proximal, z lateral):

* femoral_condyle.stl (thigh): the distal and posterior part of a cylinder of radius
  25 mm about the knee axis (z through the thigh's knee frame at y = -200 mm), from 60
  degrees anterior of straight down to 110 degrees posterior of it, 40 mm wide, with
  rounded ends: 4 mm of fillet of radius 5 mm on each side, which bend the surface 2 mm
  toward the axis, so that the contact line of the cylinder ends inside the mesh instead
  of at its border (48 mm wide in all); normals point away from the axis.
* tibial_plateau.stl (shank): a shallow concave cylindrical trough of radius 40 mm whose
  lowest line lies 25 mm below the shank's knee frame (y = 175 mm) and touches the
  condyle at full extension, ±35 degrees wide in the sagittal plane, 50 mm wide; normals
  point up, toward the condyle.

For the 3-DOF tibiofemoral example (examples/knee/tibiofemoral_3dof.yaml), in the femur's
and tibia's knee frames (origin at the knee centre):

* condyle_medial.stl, condyle_lateral.stl (femur): sphere caps of radius 20 mm centred
  at z = ∓22 mm, around the direction 30 degrees posterior of straight down, 75 degrees
  half-angle, so they face the tibia from extension to deep flexion; normals outward.
* plateau_medial.stl, plateau_lateral.stl (tibia): flat 36 mm × 30 mm patches at
  y = −20 mm (touching the condyles' lowest points at extension), z = ∓22 mm; normals up.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh

CONDYLE_RADIUS = 25.0  # mm
KNEE_Y_THIGH = -200.0  # mm, the knee axis in the thigh frame
PLATEAU_RADIUS = 40.0  # mm
PLATEAU_LOW_Y = 175.0  # mm, the trough's lowest line in the shank frame
EDGE = 1.0  # mm, target edge length
CONDYLE_WIDTH = 40.0  # mm, the cylindrical part
FILLET_RADIUS = 5.0  # mm, the rounded ends' radius ...
FILLET_WIDTH = 4.0  # mm, ... and their extent along the axis on each side


def cylinder_patch(radius, centre_xy, angle_from, angle_to, width, outward, fillet=None):
    """Vertices (n, 3) mm and faces (m, 3) of a cylindrical patch about the z axis through
    centre_xy, angles in rad (0 = +x, counter-clockwise), z in ±width/2. ``outward``:
    normals point away from the axis, else toward it. ``fillet`` (radius, extent) mm:
    the patch goes on past ±width/2 by ``extent`` on each side, its radius falling as a
    circle of that radius tangent to the cylinder (rounded ends)."""
    n_a = max(2, int(np.ceil(radius * abs(angle_to - angle_from) / EDGE)) + 1)
    half = width / 2 + (fillet[1] if fillet else 0.0)
    n_z = max(2, int(np.ceil(2 * half / EDGE)) + 1)
    a = np.linspace(angle_from, angle_to, n_a)
    z = np.linspace(-half, half, n_z)
    A, Z = np.meshgrid(a, z, indexing="ij")
    r = np.full_like(Z, radius)
    if fillet:
        past = np.clip(np.abs(Z) - width / 2, 0.0, None)
        r = radius - (fillet[0] - np.sqrt(fillet[0] ** 2 - past**2))
    V = np.stack([centre_xy[0] + r * np.cos(A), centre_xy[1] + r * np.sin(A), Z], axis=-1).reshape(-1, 3)
    idx = np.arange(n_a * n_z).reshape(n_a, n_z)
    q0, q1, q2, q3 = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    # with angle increasing along i and z along j, (q0, q1, q2) winds with its normal
    # along (∂/∂angle × ∂/∂z) = outward from the axis
    F = np.concatenate([np.stack([q0, q1, q2], -1).reshape(-1, 3), np.stack([q0, q2, q3], -1).reshape(-1, 3)])
    if not outward:
        F = F[:, ::-1]
    return V, F


def flat_patch_y(centre, size_x, size_z):
    """A flat rectangle in the plane y = centre[1], normals +y (vertices mm, faces)."""
    n_x = int(np.ceil(size_x / EDGE)) + 1
    n_z = int(np.ceil(size_z / EDGE)) + 1
    X, Z = np.meshgrid(np.linspace(-size_x / 2, size_x / 2, n_x), np.linspace(-size_z / 2, size_z / 2, n_z),
                       indexing="ij")
    V = np.stack([centre[0] + X, np.full_like(X, centre[1]), centre[2] + Z], axis=-1).reshape(-1, 3)
    idx = np.arange(n_x * n_z).reshape(n_x, n_z)
    q0, q1, q2, q3 = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    # ∂/∂x × ∂/∂z = −y: reverse the winding for +y normals
    F = np.concatenate([np.stack([q0, q2, q1], -1).reshape(-1, 3), np.stack([q0, q3, q2], -1).reshape(-1, 3)])
    return V, F


def write_tibiofemoral_meshes(out_dir):
    """The four surfaces of the 3-DOF tibiofemoral example (module docstring)."""
    from openfdk.contact.shapes import sphere_cap

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    pole = np.array([-np.sin(np.radians(30)), -np.cos(np.radians(30)), 0.0])
    for side, z in (("medial", -22.0), ("lateral", 22.0)):
        cap = sphere_cap(20.0, np.radians(75), EDGE, pole=pole, center=(0.0, 0.0, z), name=side)
        paths.append(out / f"condyle_{side}.stl")
        trimesh.Trimesh(cap.vertices_B, cap.faces, process=False).export(paths[-1])
        V, F = flat_patch_y((0.0, -20.0, z), 36.0, 30.0)
        paths.append(out / f"plateau_{side}.stl")
        trimesh.Trimesh(V, F, process=False).export(paths[-1])
    return paths


def write_meshes(out_dir):
    """Write both STL files into ``out_dir`` (created); returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    down = -np.pi / 2
    V, F = cylinder_patch(CONDYLE_RADIUS, (0.0, KNEE_Y_THIGH), down - np.radians(110), down + np.radians(60),
                          CONDYLE_WIDTH, True, fillet=(FILLET_RADIUS, FILLET_WIDTH))
    condyle = out / "femoral_condyle.stl"
    trimesh.Trimesh(V, F, process=False).export(condyle)
    V, F = cylinder_patch(PLATEAU_RADIUS, (0.0, PLATEAU_LOW_Y + PLATEAU_RADIUS), down - np.radians(35),
                          down + np.radians(35), 50.0, False)
    plateau = out / "tibial_plateau.stl"
    trimesh.Trimesh(V, F, process=False).export(plateau)
    return condyle, plateau


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent / "meshes"
    for path in [*write_meshes(target), *write_tibiofemoral_meshes(target)]:
        print(path)
