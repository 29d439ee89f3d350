"""Write the STL meshes of the knee contact example (examples/knee/knee_contact.yaml).

    python examples/knee/make_meshes.py [OUTPUT_DIR]     (default: examples/knee/meshes)

Both surfaces are generated here from simple shapes (no third-party files), in mm, in
their body frames (x anterior, y proximal, z lateral):

* femoral_condyle.stl (thigh): the distal and posterior part of a cylinder of radius
  25 mm about the knee axis (z through the thigh's knee frame at y = -200 mm), from 60
  degrees anterior of straight down to 110 degrees posterior of it, 40 mm wide; normals
  point away from the axis.
* tibial_plateau.stl (shank): a shallow concave cylindrical trough of radius 40 mm whose
  lowest line lies 25 mm below the shank's knee frame (y = 175 mm) and touches the
  condyle at full extension, ±35 degrees wide in the sagittal plane, 50 mm wide; normals
  point up, toward the condyle.
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


def cylinder_patch(radius, centre_xy, angle_from, angle_to, width, outward):
    """Vertices (n, 3) mm and faces (m, 3) of a cylindrical patch about the z axis through
    centre_xy, angles in rad (0 = +x, counter-clockwise), z in ±width/2. ``outward``:
    normals point away from the axis, else toward it."""
    n_a = max(2, int(np.ceil(radius * abs(angle_to - angle_from) / EDGE)) + 1)
    n_z = max(2, int(np.ceil(width / EDGE)) + 1)
    a = np.linspace(angle_from, angle_to, n_a)
    z = np.linspace(-width / 2, width / 2, n_z)
    A, Z = np.meshgrid(a, z, indexing="ij")
    V = np.stack([centre_xy[0] + radius * np.cos(A), centre_xy[1] + radius * np.sin(A), Z], axis=-1).reshape(-1, 3)
    idx = np.arange(n_a * n_z).reshape(n_a, n_z)
    q0, q1, q2, q3 = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    # with angle increasing along i and z along j, (q0, q1, q2) winds with its normal
    # along (∂/∂angle × ∂/∂z) = outward from the axis
    F = np.concatenate([np.stack([q0, q1, q2], -1).reshape(-1, 3), np.stack([q0, q2, q3], -1).reshape(-1, 3)])
    if not outward:
        F = F[:, ::-1]
    return V, F


def write_meshes(out_dir):
    """Write both STL files into ``out_dir`` (created); returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    down = -np.pi / 2
    V, F = cylinder_patch(CONDYLE_RADIUS, (0.0, KNEE_Y_THIGH), down - np.radians(110), down + np.radians(60), 40.0, True)
    condyle = out / "femoral_condyle.stl"
    trimesh.Trimesh(V, F, process=False).export(condyle)
    V, F = cylinder_patch(PLATEAU_RADIUS, (0.0, PLATEAU_LOW_Y + PLATEAU_RADIUS), down - np.radians(35),
                          down + np.radians(35), 50.0, False)
    plateau = out / "tibial_plateau.stl"
    trimesh.Trimesh(V, F, process=False).export(plateau)
    return condyle, plateau


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent / "meshes"
    for path in write_meshes(target):
        print(path)
