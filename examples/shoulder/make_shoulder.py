"""Write the shoulder example's meshes and a synthetic marker trial (docs/tutorial-shoulder.md).

    python examples/shoulder/make_shoulder.py [OUT_DIR]     # default: next to this file

meshes/humeral_head.stl  sphere cap, radius 25 mm, on the humerus (normals outward)
meshes/glenoid.stl       concave spherical cup, radius 27 mm, half-angle 50 deg, on the thorax (normals
                         toward the cup's centre, i.e. out of the bone into the joint)
reach.trc                2 s at 100 Hz: shoulder flexion 0 -> 60 deg and elbow flexion
                         10 -> 90 deg, 1 mm marker noise, a 60 ms gap of marker H3

Only numpy is used; the STL files are ASCII, in mm.
"""

import sys
from pathlib import Path

import numpy as np

HEAD_RADIUS = 25.0          # mm
GLENOID_RADIUS = 27.0       # mm: 2 mm larger than the head (a congruent cup makes FDK fail, see the docs)
GH = np.array([0.0, 0.0, 180.0])        # glenohumeral centre in the thorax (= world) frame, mm
ELBOW = np.array([0.0, -300.0, 180.0])  # elbow centre in the reference pose, mm
# markers in the world frame at the reference pose (arm hanging, elbow straight), mm
HUMERUS_MARKERS = {"H1": [0.0, -120.0, 215.0], "H2": [40.0, -200.0, 200.0],
                   "H3": [-35.0, -220.0, 205.0], "LEPI": [0.0, -300.0, 215.0]}
FOREARM_MARKERS = {"F1": [30.0, -400.0, 200.0], "F2": [-30.0, -420.0, 200.0],
                   "RSTY": [20.0, -540.0, 205.0], "USTY": [-20.0, -540.0, 160.0]}


def cap(radius, half_angle, pole, n_rings=14, n_seg=40):
    """Vertices (n, 3) and faces (m, 3) of a sphere cap around unit `pole`, centre at 0,
    wound so that the right-hand normals point outward (away from the centre)."""
    pole = np.asarray(pole, float) / np.linalg.norm(pole)
    a = np.cross(pole, [1.0, 0.0, 0.0] if abs(pole[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(pole, a)
    verts = [radius * pole]
    for i in range(1, n_rings + 1):
        th = half_angle * i / n_rings
        for j in range(n_seg):
            ph = 2 * np.pi * j / n_seg
            verts.append(radius * (np.cos(th) * pole + np.sin(th) * (np.cos(ph) * a + np.sin(ph) * b)))
    faces = []
    for j in range(n_seg):
        faces.append([0, 1 + j, 1 + (j + 1) % n_seg])
    for i in range(n_rings - 1):
        r0, r1 = 1 + i * n_seg, 1 + (i + 1) * n_seg
        for j in range(n_seg):
            k = (j + 1) % n_seg
            faces.append([r0 + j, r1 + j, r1 + k])
            faces.append([r0 + j, r1 + k, r0 + k])
    return np.array(verts), np.array(faces)


def write_stl(path, verts, faces):
    """ASCII STL; facet normals from the right-hand rule."""
    lines = ["solid openfdk"]
    for f in faces:
        p = verts[f]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        n /= np.linalg.norm(n)
        lines.append(f"  facet normal {n[0]:.6e} {n[1]:.6e} {n[2]:.6e}\n    outer loop")
        lines += [f"      vertex {v[0]:.6e} {v[1]:.6e} {v[2]:.6e}" for v in p]
        lines.append("    endloop\n  endfacet")
    lines.append("endsolid openfdk")
    Path(path).write_text("\n".join(lines) + "\n")


def rot(axis, angle):
    """Rotation matrix about a unit axis (rad)."""
    k = np.asarray(axis, float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def trial(rate=100.0, duration=2.0, noise=1.0, seed=1):
    """(t (nf,), labels, x (nf, n, 3) mm) of the reaching motion, with noise and a gap."""
    t = np.arange(int(round(duration * rate)) + 1) / rate
    s = 0.5 * (1 - np.cos(np.pi * t / duration))                # smooth 0 -> 1
    flex = np.deg2rad(60.0) * s                                 # shoulder flexion about +z
    abd = np.deg2rad(10.0) * s                                  # a little abduction, about -x
    elbow = np.deg2rad(10.0 + 80.0 * s)                         # elbow flexion about +z
    labels = list(HUMERUS_MARKERS) + list(FOREARM_MARKERS)
    x = np.zeros((len(t), len(labels), 3))
    for f in range(len(t)):
        R_hum = rot([0, 0, 1], flex[f]) @ rot([-1, 0, 0], abd[f])
        R_fore = R_hum @ rot([0, 0, 1], elbow[f])
        e_W = GH + R_hum @ (ELBOW - GH)
        for m, p in enumerate(HUMERUS_MARKERS.values()):
            x[f, m] = GH + R_hum @ (np.array(p) - GH)
        for m, p in enumerate(FOREARM_MARKERS.values()):
            x[f, len(HUMERUS_MARKERS) + m] = e_W + R_fore @ (np.array(p) - ELBOW)
    x += np.random.default_rng(seed).normal(scale=noise, size=x.shape)
    gap = (t >= 0.80) & (t < 0.86)
    x[gap, labels.index("H3")] = np.nan
    return t, labels, x


def write_trc(path, t, labels, x, rate):
    """An OpenSim TRC file (mm)."""
    head = [f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"{rate:g}\t{rate:g}\t{len(t)}\t{len(labels)}\tmm\t{rate:g}\t1\t{len(t)}",
            "Frame#\tTime\t" + "\t\t\t".join(labels),
            "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(len(labels))),
            ""]
    rows = []
    for f in range(len(t)):
        vals = ["" if np.isnan(v) else f"{v:.4f}" for v in x[f].ravel()]
        rows.append(f"{f + 1}\t{t[f]:.4f}\t" + "\t".join(vals))
    Path(path).write_text("\n".join(head + rows) + "\n")


def main(out=None):
    out = Path(out) if out else Path(__file__).parent
    (out / "meshes").mkdir(parents=True, exist_ok=True)
    v, f = cap(HEAD_RADIUS, np.deg2rad(60), pole=[0, 0, -1])    # faces the glenoid (medial)
    write_stl(out / "meshes" / "humeral_head.stl", v, f)
    v, f = cap(GLENOID_RADIUS, np.deg2rad(50), pole=[0, 0, -1], n_rings=14, n_seg=32)   # with the labrum
    write_stl(out / "meshes" / "glenoid.stl", v, f[:, ::-1])   # concave side: normals inward
    t, labels, x = trial()
    write_trc(out / "reach.trc", t, labels, x, 100.0)
    return out


if __name__ == "__main__":
    print(main(sys.argv[1] if len(sys.argv) > 1 else None))
