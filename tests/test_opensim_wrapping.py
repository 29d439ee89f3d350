"""OpenSim wrapping in: PathWrap over WrapCylinder, WrapSphere and WrapEllipsoid
(``quadrant``, the PathWrap ``range``, wrap objects on offset frames and welded
bodies, paths with conditional and moving points), against OpenSim 4.6 as the oracle
(docs/opensim-import.md, wrapping).

The models are built with OpenSim's API and printed by it; OpenSim reads the file back
(``opensim.Model(path)``) and openfdk imports it. At random poses (wrapping and lifted
off) each muscle's length is compared with OpenSim's ``getLength`` and its moment arm
with OpenSim's ``computeMomentArm``.
"""

from __future__ import annotations

import numpy as np
import pytest
from lxml import etree

opensim = pytest.importorskip("opensim")

import opensim_models as om  # noqa: E402  (tests/opensim_models.py)

from openfdk.io.modelfile import model_from_dict  # noqa: E402
from openfdk.io.opensim import OsimError, read_osim  # noqa: E402
from openfdk.kinematics.coordinate_pose import pose_from_coordinates  # noqa: E402

#: the wrap objects: (type, name, owner, translation, xyz_body_rotation, quadrant, size)
WRAPS = [
    ("WrapCylinder", "elbow_cyl", "upper", (0.002, -0.3, 0.004), (0.1, -0.05, 0.2), "all", (0.025, 0.2)),
    ("WrapCylinder", "elbow_back", "upper", (-0.001, -0.3, -0.002), (-0.05, 0.08, 0.3), "-x", (0.022, 0.2)),
    ("WrapCylinder", "short_cyl", "upper", (0.0, -0.3, 0.0), (0.0, 0.0, 0.0), "all", (0.02, 0.03)),
    ("WrapSphere", "head", "ground", (0.003, 1.0, 0.002), (0.3, 0.2, 0.1), "all", (0.03,)),
    ("WrapEllipsoid", "condyle", "cap_frame", (0.004, 0.01, -0.003), (0.2, -0.3, 0.4), "all", (0.035, 0.022, 0.03)),
]
#: the muscles: name -> (points (name, body, location), path wraps (wrap object, range))
MUSCLES = {
    "tri": ([("o", "upper", (-0.03, -0.1, 0.0)), ("i", "fore", (-0.03, -0.04, 0.01))], [("elbow_cyl", None)]),
    "tri_back": ([("o", "upper", (-0.028, -0.12, 0.004)), ("i", "fore", (-0.032, -0.045, -0.006))],
                 [("elbow_back", None)]),
    "tri_short": ([("o", "upper", (-0.025, -0.1, 0.015)), ("i", "fore", (-0.03, -0.04, -0.02))], [("short_cyl", None)]),
    "delt": ([("o", "ground", (0.05, 1.06, 0.01)), ("i", "upper", (0.03, -0.08, 0.005))], [("head", None)]),
    "brach": ([("o", "upper", (0.035, -0.15, 0.0)), ("i", "fore", (0.03, -0.06, 0.004))], [("condyle", None)]),
    "tri_long": ([("o", "ground", (-0.02, 1.03, 0.0)), ("v1", "upper", (-0.04, -0.15, 0.0)),
                  ("v2", "upper", (-0.035, -0.25, 0.005)), ("i", "fore", (-0.03, -0.04, 0.0))],
                 [("elbow_cyl", (3, 4))]),
    "tri_all": ([("o", "ground", (-0.02, 1.03, 0.0)), ("v1", "upper", (-0.04, -0.15, 0.0)),
                 ("v2", "upper", (-0.036, -0.24, 0.004)), ("i", "fore", (-0.03, -0.04, 0.0))],
                [("elbow_cyl", None)]),
}


def wrap_model(path, wraps=WRAPS, muscles=MUSCLES):
    """Ground, ``upper`` (pin at the shoulder), ``fore`` (pin at the elbow, z of the
    upper arm's frame at (0, −0.3, 0)) and ``cap`` welded to the forearm with an offset
    frame ``cap_frame`` that holds a wrap object; Thelen2003Muscles over the wraps."""
    m = opensim.Model()
    m.setName("wrap_arm")
    upper = opensim.Body("upper", 2.0, om.vec3((0.01, -0.15, 0.02)), opensim.Inertia(0.02, 0.01, 0.02, 0.001, 0, 0))
    fore = opensim.Body("fore", 1.0, om.vec3((0.0, -0.12, -0.01)), opensim.Inertia(0.01, 0.005, 0.01))
    cap = opensim.Body("cap", 0.2, om.vec3((0.01, 0.0, 0.0)), opensim.Inertia(0.001, 0.001, 0.001))
    for b in (upper, fore, cap):
        m.addBody(b)
    m.addJoint(opensim.PinJoint("shoulder", m.getGround(), om.vec3((0, 1, 0)), om.vec3((0, 0, 0)),
                                upper, om.vec3((0, 0.0, 0)), om.vec3((0, 0, 0))))
    m.addJoint(opensim.PinJoint("elbow", upper, om.vec3((0, -0.3, 0)), om.vec3((0, 0, 0)),
                                fore, om.vec3((0, 0.0, 0)), om.vec3((0, 0, 0))))
    m.addJoint(opensim.WeldJoint("cap_weld", fore, om.vec3((0.01, 0.02, 0.0)), om.vec3((0.1, 0.0, -0.2)),
                                 cap, om.vec3((0, 0, 0)), om.vec3((0, 0, 0))))
    m.getJointSet().get("shoulder").updCoordinate().setName("q_shoulder")
    m.getJointSet().get("elbow").updCoordinate().setName("q_elbow")
    cap_frame = opensim.PhysicalOffsetFrame("cap_frame", cap, opensim.Transform(
        opensim.Rotation(0.3, opensim.CoordinateAxis(2)), om.vec3((-0.01, -0.02, 0.0))))
    cap.addComponent(cap_frame)
    owners = {"ground": m.getGround(), "upper": upper, "fore": fore, "cap": cap, "cap_frame": cap_frame}
    objects = {}
    for kind, name, owner, t, r, quadrant, size in wraps:
        w = getattr(opensim, kind)()
        w.setName(name)
        w.set_translation(om.vec3(t))
        w.set_xyz_body_rotation(om.vec3(r))
        w.set_quadrant(quadrant)
        if kind == "WrapCylinder":
            w.set_radius(size[0])
            w.set_length(size[1])
        elif kind == "WrapSphere":
            w.set_radius(size[0])
        elif kind == "WrapTorus":
            w.set_inner_radius(size[0])
            w.set_outer_radius(size[1])
        else:
            w.set_dimensions(om.vec3(size))
        owners[owner].addWrapObject(w)
        objects[name] = w
    bodies = {"ground": m.getGround(), "upper": upper, "fore": fore, "cap": cap}
    for name, (points, pws) in muscles.items():
        mu = opensim.Thelen2003Muscle(name, 500.0, 0.1, 0.2, 0.0)
        for pname, body, loc in points:
            mu.addNewPathPoint(pname, bodies[body], om.vec3(loc))
        for wname, rng in pws:
            mu.updGeometryPath().addPathWrap(objects[wname])
            if rng is not None:
                ws = mu.updGeometryPath().updWrapSet()
                pw = ws.get(ws.getSize() - 1)
                pw.set_range(0, rng[0])
                pw.set_range(1, rng[1])
        m.addForce(mu)
    m.finalizeConnections()
    assert m.printToXML(str(path))
    return path


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("osim_wrapping")


@pytest.fixture(autouse=True)
def _in_workdir(workdir, monkeypatch):
    monkeypatch.chdir(workdir)  # OpenSim writes opensim.log into the cwd


@pytest.fixture(scope="module")
def model(workdir):
    return wrap_model(workdir / "wrap_arm.osim")


def compare(path, n=30, seed=0, q_range=(-1.5, 1.5), exact=False, their_fd=False):
    """Per muscle over ``n`` random poses: {"dl": largest relative |Δl| against OpenSim's
    ``getLength``, "shorter": largest (l − l_OpenSim)/l (≤ 0: OpenSim's path is never
    shorter than openfdk's), "dr": largest |Δr| m against ``computeMomentArm``, "dr_self": largest |r −
    (−∂l/∂q)| m of openfdk's analytic moment arm against a central difference of its own
    length, "wrapped": poses where OpenSim's path wraps, "exact": largest relative
    |l − l*| against an independent minimisation (cylinders and spheres, ``exact``),
    "r_min": the smallest largest |r| of a pose (m), "active"/"inactive": poses with all
    points in the path or not, and with ``their_fd`` "dr_fd": largest |Δr| m against
    −∂l/∂q of OpenSim's length (central difference, step 1e-6)}."""
    data, _ = read_osim(path)
    ours = model_from_dict(data, source=str(path))
    theirs = opensim.Model(str(path))
    state = theirs.initSystem()
    coords = [theirs.getCoordinateSet().get(k) for k in range(theirs.getCoordinateSet().getSize())]
    muscles = [theirs.getMuscles().get(k) for k in range(theirs.getMuscles().getSize())]
    by_name = {m.name: m for m in ours.muscles}
    rng = np.random.default_rng(seed)
    out = {mu.getName(): dict(dl=0.0, shorter=-np.inf, dr=0.0, dr_self=0.0, wrapped=0, exact=0.0, dr_fd=0.0,
                              r_min=np.inf, active=0, inactive=0) for mu in muscles}
    h = 1e-6
    for _ in range(n):
        q = {c.getName(): float(rng.uniform(*q_range)) for c in coords}
        for c in coords:
            c.setValue(state, q[c.getName()], False)
        theirs.realizePosition(state)
        st0, _ = pose_from_coordinates(ours, q)
        moved = {}
        for c in coords:
            st, _ = pose_from_coordinates(ours, q, qdot={c.getName(): 1.0})
            st_p, _ = pose_from_coordinates(ours, {**q, c.getName(): q[c.getName()] + h}, state=st.copy())
            st_m, _ = pose_from_coordinates(ours, {**q, c.getName(): q[c.getName()] - h}, state=st.copy())
            moved[c.getName()] = (st, st_p, st_m)
        for mu in muscles:
            rec = out[mu.getName()]
            path_ = by_name[mu.getName()].path
            length = float(np.ravel(path_.evaluate(st0, 0)[0])[0])
            theirs_l = mu.getLength(state)
            rec["dl"] = max(rec["dl"], abs(length - theirs_l) / theirs_l)
            rec["shorter"] = max(rec["shorter"], (length - theirs_l) / length)
            gp = mu.getGeometryPath()
            n_active = sum(gp.getPathPointSet().get(k).isActive(state) for k in range(gp.getPathPointSet().getSize()))
            rec["wrapped"] += gp.getCurrentPath(state).getSize() > n_active
            full = n_active == gp.getPathPointSet().getSize()
            rec["active"] += full
            rec["inactive"] += not full
            r_pose = 0.0
            if exact:
                if "ellipsoid" not in {getattr(nd, "kind", "") for nd in path_.nodes}:
                    rec["exact"] = max(rec["exact"], abs(length - shortest_length(path_, st0)) / length)
            for c in coords:
                st, st_p, st_m = moved[c.getName()]
                _, L, _ = path_.evaluate(st, 1)
                r = -float(np.ravel(np.asarray(L) @ st.get_v())[0])
                r_fd = -(float(np.ravel(path_.evaluate(st_p, 0)[0])[0]) - float(np.ravel(path_.evaluate(st_m, 0)[0])[0])) / (2 * h)
                rec["dr"] = max(rec["dr"], abs(r - mu.computeMomentArm(state, c)))
                rec["dr_self"] = max(rec["dr_self"], abs(r - r_fd))
                r_pose = max(r_pose, abs(r))
                if their_fd:
                    q0 = q[c.getName()]
                    lengths = []
                    for qq in (q0 + h, q0 - h):
                        c.setValue(state, qq, False)
                        theirs.realizePosition(state)
                        lengths.append(mu.getLength(state))
                    c.setValue(state, q0, False)
                    theirs.realizePosition(state)
                    rec["dr_fd"] = max(rec["dr_fd"], abs(r + (lengths[0] - lengths[1]) / (2 * h)))
            rec["r_min"] = min(rec["r_min"], r_pose)
    return out


def _enters(a, b, r):
    """A penalty (m) for the straight segment a→b passing inside radius r of the origin
    (the segments of a wrapped path stay outside the surface)."""
    d = b - a
    t = np.clip(-(a @ d) / (d @ d), 0.0, 1.0)
    gap = r - np.linalg.norm(a + t * d)
    return 1e3 * gap if gap > 1e-12 * r else 0.0


def shortest_length(path, state):
    """The length of the shortest path through the same points that passes each surface
    openfdk's path touches on the same side, by direct minimisation (scipy) over the
    tangent points (cylinder: angle and height of each; sphere: a great-circle arc):
    an oracle independent of openfdk's closed forms. Started from openfdk's tangent
    points, so it checks that they make the path shortest."""
    from scipy.optimize import minimize

    _, _, T = path.kernel.evaluate(state, with_tangents=True)
    nodes = path.nodes
    total = 0.0
    prev = None
    for k, node in enumerate(nodes):
        if not hasattr(node, "kind"):
            x = state.p_WB[node[0]] + state.R_WB[node[0]] @ node[1]
            if prev is not None:
                total += np.linalg.norm(x - prev)
            prev = x
            continue
        if np.isnan(T[k, 0, 0]):
            continue
        assert node.kind in ("cylinder", "sphere")
        R = state.R_WB[node.body] @ node.R_BS
        o = state.p_WB[node.body] + state.R_WB[node.body] @ node.p_BS
        nxt = next(n for n in nodes[k + 1:] if not hasattr(n, "kind"))
        P = R.T @ (prev - o)
        Q = R.T @ (state.p_WB[nxt[0]] + state.R_WB[nxt[0]] @ nxt[1] - o)
        T1, T2 = R.T @ (T[k, 0] - o), R.T @ (T[k, 1] - o)
        r = node.dims[0]
        if node.kind == "cylinder":
            a1, a2 = np.arctan2(T1[1], T1[0]), np.arctan2(T2[1], T2[0])
            d = T1 - P  # the way round: the direction the path arrives at T1 (in x, y)
            sign = 1.0 if T1[0] * d[1] - T1[1] * d[0] > 0.0 else -1.0
            sweep = np.mod(sign * (a2 - a1), 2 * np.pi)

            def f(x):
                t1 = np.array([r * np.cos(x[0]), r * np.sin(x[0]), x[1]])
                t2 = np.array([r * np.cos(x[0] + sign * x[2]), r * np.sin(x[0] + sign * x[2]), x[3]])
                return (np.linalg.norm(t1 - P) + np.hypot(r * x[2], x[3] - x[1]) + np.linalg.norm(Q - t2)
                        + _enters(P[:2], t1[:2], r) + _enters(t2[:2], Q[:2], r))

            x0 = [a1, T1[2], sweep, T2[2]]
        else:
            def f(x):
                u = np.array([np.cos(x[0]) * np.cos(x[1]), np.cos(x[0]) * np.sin(x[1]), np.sin(x[0])])
                v = np.array([np.cos(x[2]) * np.cos(x[3]), np.cos(x[2]) * np.sin(x[3]), np.sin(x[2])])
                ang = np.arccos(np.clip(u @ v, -1, 1))
                return (np.linalg.norm(r * u - P) + r * ang + np.linalg.norm(Q - r * v)
                        + _enters(P, r * u, r) + _enters(r * v, Q, r))

            u0, v0 = T1 / r, T2 / r
            x0 = [np.arcsin(u0[2]), np.arctan2(u0[1], u0[0]), np.arcsin(v0[2]), np.arctan2(v0[1], v0[0])]
        best = minimize(f, x0, method="Nelder-Mead", options=dict(xatol=1e-12, fatol=1e-15, maxiter=20000))
        total += best.fun - np.linalg.norm(Q - P)  # the straight P→Q is added by the next point
    return total


N_POSES = 30


@pytest.fixture(scope="module")
def differences(model):
    return compare(model, n=N_POSES, exact=True)


def test_import_maps_wrap_objects_and_ranges(model):
    """Each wrap object becomes a surface on its (merged) body: the ellipsoid on the offset
    frame of the body welded to the forearm lands on the forearm; a quadrant becomes a
    side; a PathWrap's range lists the surface in each segment of the range."""
    data, _ = read_osim(model)
    w = data["wrapping"]
    assert w["condyle"]["frame"].startswith("fore.") and w["condyle"]["type"] == "ellipsoid"
    assert w["elbow_back"]["side"] == "-x" and "side" not in w["elbow_cyl"]
    assert w["short_cyl"]["length"] == pytest.approx(0.03) and w["head"]["radius"] == pytest.approx(0.03)
    assert all(e["inside"] == "straight" and e["one_segment"] for e in w.values())
    muscles = data["muscles"]
    assert muscles["tri_long"]["path"] == ["ground.tri_long_o", "upper.tri_long_v1", "upper.tri_long_v2", "elbow_cyl",
                                           "fore.tri_long_i"]
    assert muscles["tri_all"]["path"][1::2] == ["elbow_cyl"] * 3


def test_sphere_equals_opensim(differences):
    """WrapSphere (OpenSim's great circle is exact): length ≤ 1e-12 relative, moment arms
    equal ``computeMomentArm`` to 1e-9 m, at poses wrapped and lifted off."""
    d = differences["delt"]
    print("sphere", d)
    assert 0 < d["wrapped"] < N_POSES
    assert d["dl"] <= 1e-12 and d["dr"] <= 1e-9 and d["exact"] <= 1e-12 and d["dr_self"] <= 1e-8


@pytest.mark.parametrize("quadrant", ["+x", "-y", "+z"])
def test_sphere_with_quadrant_equals_opensim(workdir, quadrant):
    """A WrapSphere with a quadrant: OpenSim wraps only while the straight line crosses
    the sphere and then goes round the quadrant's side (openfdk: ``crossing_only`` and
    ``side``): lengths ≤ 1e-12 relative, moment arms ≤ 1e-9 m, wrapped and lifted off."""
    wraps = [("WrapSphere", "head", "ground", (0.003, 1.0, 0.002), (0.3, 0.2, 0.1), quadrant, (0.03,))]
    path = wrap_model(workdir / f"sphere{quadrant}.osim", wraps, {"delt": MUSCLES["delt"]})
    d = compare(path, n=N_POSES)["delt"]
    print(quadrant, d)
    assert 0 < d["wrapped"] < N_POSES and d["dl"] <= 1e-12 and d["dr"] <= 1e-9


@pytest.mark.parametrize("name", ["tri", "tri_back", "tri_short", "tri_long", "tri_all"])
def test_cylinders_are_shortest_and_within_opensims_approximation(differences, name):
    """WrapCylinder without and with a quadrant, of finite length, over a one-segment
    PathWrap range and over the whole path: openfdk's length equals the shortest path
    (an independent minimisation over the tangent points) to 1e-12 relative; OpenSim's
    is never shorter and is longer by at most 3e-5 relative (1.7e-5 measured): with one
    PathWrap, OpenSim 4.6 skips its tangency iteration (opensim-core #3125), so its
    tangent points are not quite tangent. Its ``computeMomentArm`` differs by the same
    cause (6e-5 m measured, ≤ 1e-4 m asserted); openfdk's moment arm is the derivative of
    its length (≤ 1e-8 m against a central difference)."""
    d = differences[name]
    print(name, d)
    assert 0 < d["wrapped"] < N_POSES
    assert d["exact"] <= 1e-12 and d["shorter"] <= 1e-12
    assert d["dl"] <= 3e-5 and d["dr"] <= 1e-4 and d["dr_self"] <= 1e-8


def test_ellipsoid_within_opensims_approximation(differences):
    """WrapEllipsoid on an offset frame of a body welded to the forearm: openfdk's path is
    the geodesic; OpenSim's (any ``method``) follows a curve in a plane through the two
    anchors (longer) and measures it as a polyline of ~1 mm chords (shorter): its length
    differs by at most 1e-4 relative (4.3e-5 measured, either sign), its
    ``computeMomentArm`` by up to 2e-3 m (1.0e-3 measured). openfdk's moment arm is the
    derivative of its length (≤ 1e-8 m against a central difference)."""
    d = differences["brach"]
    print("ellipsoid", d)
    assert 0 < d["wrapped"] < N_POSES
    assert d["dl"] <= 1e-4 and d["dr"] <= 2e-3 and d["dr_self"] <= 1e-8


@pytest.mark.parametrize("quadrant", ["+x", "-y", "+z"])
def test_ellipsoid_with_quadrant_equals_opensim(workdir, quadrant):
    """A WrapEllipsoid with a quadrant follows OpenSim's own rule (surface ``rule:
    opensim``, forces/wrap_ellipsoid_plane.py): a curve in the plane through both anchors
    and a surface point c1 reflected into the quadrant, measured as OpenSim's polyline of
    ~1 mm chords. At 30 random poses (wrapped and not): lengths within 1e-5 relative of
    OpenSim's ``getLength``; the rest is OpenSim's tangent-point search, which stops at
    squared residuals below 1e-8 (its tangent points differ from the exact ones by up to
    2e-6 m, measured). The length is not stationary in the tangent points (the plane is a
    heuristic), so openfdk's moment arm adds the plane's terms: it is the derivative of its
    length (≤ 1e-7 m against a central difference, 1.9e-10 measured; non-zero) and within
    2e-5 m of −∂l/∂q of OpenSim's own length (5.1e-6 measured at +x). OpenSim's
    ``computeMomentArm`` holds its tangent points fixed and misses those terms: it is not
    the derivative of OpenSim's own length, 2.1e-2 m off at +x (≤ 5e-2 m asserted, a
    record of OpenSim's inconsistency, not a tolerance of openfdk)."""
    wraps = [("WrapEllipsoid", "condyle", "cap_frame", (0.004, 0.01, -0.003), (0.2, -0.3, 0.4), quadrant,
              (0.035, 0.022, 0.03))]
    path = wrap_model(workdir / f"ellipsoid{quadrant}.osim", wraps, {"brach": MUSCLES["brach"]})
    d = compare(path, n=N_POSES, their_fd=True)["brach"]
    print(quadrant, d)
    assert 0 < d["wrapped"] < N_POSES and d["r_min"] > 1e-3
    assert d["dl"] <= 1e-5 and d["dr_self"] <= 1e-7 and d["dr_fd"] <= 2e-5 and d["dr"] <= 5e-2


@pytest.mark.parametrize("name", ["tri", "tri_back", "delt", "brach"])
def test_lift_off_where_opensims(model, name):
    """The pose where the path leaves the surface: bisected on OpenSim's (to 1e-10 rad
    of the elbow or shoulder), openfdk's path is straight 1e-7 rad on one side and wraps
    1e-7 rad on the other, and the lengths there equal OpenSim's to 1e-9 m (the arc is
    then too short for OpenSim's approximations to show). Both lift off where the
    straight line stops crossing the surface."""
    data, _ = read_osim(model)
    built = model_from_dict(data, source=str(model))
    ours = {m.name: m for m in built.muscles}[name]
    theirs = opensim.Model(str(model))
    state = theirs.initSystem()
    mu = theirs.getMuscles().get(name)
    coordinate = "q_shoulder" if name == "delt" else "q_elbow"
    other = "q_elbow" if name == "delt" else "q_shoulder"
    c = theirs.getCoordinateSet().get(coordinate)
    theirs.getCoordinateSet().get(other).setValue(state, 0.2, False)
    n_points = mu.getGeometryPath().getPathPointSet().getSize()

    def wraps(q):
        c.setValue(state, q, False)
        theirs.realizePosition(state)
        return mu.getGeometryPath().getCurrentPath(state).getSize() > n_points

    grid = np.linspace(-1.5, 1.5, 61)
    flags = [wraps(q) for q in grid]
    k = next(i for i in range(60) if flags[i] != flags[i + 1])
    lo, hi = grid[k], grid[k + 1]
    while hi - lo > 1e-10:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if wraps(mid) == flags[k] else (lo, mid)
    for q, wrapped in ((lo - 1e-7, flags[k]), (hi + 1e-7, not flags[k])):
        assert wraps(q) == wrapped
        st, _ = pose_from_coordinates(built, {coordinate: q, other: 0.2})
        _, _, T = ours.path.kernel.evaluate(st, with_tangents=True)
        assert (not np.all(np.isnan(T))) == wrapped, (q, wrapped)
        length = float(np.ravel(ours.path.evaluate(st, 0)[0])[0])
        assert abs(length - mu.getLength(state)) <= 1e-9, (q, length - mu.getLength(state))


def _edit(src, dst, edit):
    tree = etree.parse(str(src))
    element = edit(tree)
    tree.write(str(dst))
    return etree.parse(str(dst)).xpath(f"//{element.tag}[@name='{element.get('name')}']")[0].sourceline


def _path_wrap(tree, muscle="tri"):
    return tree.xpath(f"//Thelen2003Muscle[@name='{muscle}']//PathWrap")[0]


def _set(element, tag, text):
    e = element.find(tag)
    if e is None:
        e = etree.SubElement(element, tag)
    e.text = text
    return element


def _wrap_object(tree, name):
    return tree.xpath(f"//*[@name='{name}' and starts-with(local-name(), 'Wrap')]")[0]


@pytest.mark.parametrize("edit,words", [
    (lambda t: _set(_path_wrap(t), "wrap_object", "nope"), "unknown wrap object 'nope'"),
    (lambda t: _set(_path_wrap(t), "method", "geodesic"), "method 'geodesic'"),
    (lambda t: _set(_path_wrap(t), "range", "1 9"), "range [1, 9] beyond the path's 2 points"),
    (lambda t: _set(_wrap_object(t, "elbow_cyl"), "quadrant", "+w"), "quadrant '+w'"),
    (lambda t: _set(_wrap_object(t, "elbow_cyl"), "quadrant", "z"), "along the cylinder's axis is not supported"),
    (lambda t: _set(_wrap_object(t, "head"), "radius", "-0.01"), "must be > 0 m"),
    (lambda t: _set(_wrap_object(t, "head"), "scale", "2"), "property <scale> is not read"),
])
def test_bad_wraps_are_one_line_errors(model, workdir, edit, words):
    """An unknown wrap object, method or quadrant, a range beyond the path, a quadrant
    along a cylinder's axis, a bad size or property: one line naming the file, the line
    and the element."""
    path = workdir / "bad_wrap.osim"
    line = _edit(model, path, edit)
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert "\n" not in msg and path.name in msg and words in msg, msg
    assert f"line {line}:" in msg or "line " in msg, msg


def _conditional_point(tree, muscle, point, rng="-1 0.5"):
    p = tree.xpath(f"//Thelen2003Muscle[@name='{muscle}']//PathPoint[@name='{point}']")[0]
    p.tag = "ConditionalPathPoint"
    p.append(etree.fromstring("<socket_coordinate>/jointset/elbow/q_elbow</socket_coordinate>"))
    p.append(etree.fromstring(f"<range>{rng}</range>"))
    return p


def _moving_point(tree, muscle, point):
    """The point moves with q_elbow in its body's frame: x a SimmSpline, y a
    LinearFunction, z a Constant (m)."""
    p = tree.xpath(f"//Thelen2003Muscle[@name='{muscle}']//PathPoint[@name='{point}']")[0]
    p.tag = "MovingPathPoint"
    loc = p.find("location")
    if loc is not None:
        p.remove(loc)
    for a in "xyz":
        p.append(etree.fromstring(f"<socket_{a}_coordinate>/jointset/elbow/q_elbow</socket_{a}_coordinate>"))
    p.append(etree.fromstring("<x_location><SimmSpline><x>-2 -1 0 0.7 2</x><y>-0.045 -0.04 -0.036 -0.03 -0.028</y>"
                              "</SimmSpline></x_location>"))
    p.append(etree.fromstring("<y_location><LinearFunction><coefficients>0.01 -0.24</coefficients></LinearFunction>"
                              "</y_location>"))
    p.append(etree.fromstring("<z_location><Constant><value>0.004</value></Constant></z_location>"))
    return p


@pytest.fixture(scope="module")
def coordinate_points_model(model, workdir):
    """The wrap arm with tri_all's v1 a ConditionalPathPoint (q_elbow in [−1, 0.5]),
    tri_long's v2 (the first point of its PathWrap range 3–4) a ConditionalPathPoint
    (q_elbow in [−0.5, 1]), and tri's insertion a MovingPathPoint of q_elbow."""
    path = workdir / "coordinate_wrap.osim"
    tree = etree.parse(str(model))
    _conditional_point(tree, "tri_all", "v1")
    _conditional_point(tree, "tri_long", "v2", "-0.5 1")
    _moving_point(tree, "tri_all", "v2")
    tree.write(str(path))
    return path


def test_wraps_with_conditional_and_moving_points_equal_opensim(coordinate_points_model):
    """PathWraps over cylinders on paths with ConditionalPathPoints and a MovingPathPoint,
    at random poses on both sides of each range: the lengths equal OpenSim's to 1e-5
    relative (4.4e-7 measured; OpenSim's path is never shorter), openfdk's moment arm is
    the derivative of its length (≤ 1e-8 m) and non-zero. With a conditional point inside the PathWrap range (tri_long: range 3–4
    with point 3 inactive) OpenSim scans the range for active points and does not wrap:
    so does openfdk. Moment arms: tri_long against OpenSim's ``computeMomentArm`` (≤ 1e-5
    m, 2.0e-6 measured: the cylinder's approximation); tri_all, whose moving point's f′(q)
    term OpenSim 4.6's ``computeMomentArm`` leaves out (tests/test_opensim_muscles.py; 1 cm
    here), against −∂l/∂q of OpenSim's own length (central difference, ≤ 1e-5 m, 5.9e-7
    measured)."""
    d = compare(coordinate_points_model, n=N_POSES, their_fd=True)
    for name in ("tri_all", "tri_long"):
        rec = d[name]
        print(name, rec)
        assert 0 < rec["wrapped"] < N_POSES and rec["inactive"] > 0 and rec["active"] > 0
        assert rec["dl"] <= 1e-5 and rec["shorter"] <= 1e-12 and rec["dr_self"] <= 1e-8 and rec["r_min"] > 1e-3
    assert d["tri_long"]["dr"] <= 1e-5
    assert d["tri_all"]["dr_fd"] <= 1e-5


def test_wrapped_path_starting_at_a_conditional_point_is_refused(model, workdir):
    """A PathWrap on a path whose first point is a ConditionalPathPoint: one line naming
    the PathWrap and ``--ignore PathWrap``, which leaves the muscle out."""
    path = workdir / "conditional_end.osim"
    tree = etree.parse(str(model))
    _conditional_point(tree, "tri_long", "o")
    tree.write(str(path))
    line = _path_wrap(etree.parse(str(path)), "tri_long").sourceline
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert "\n" not in msg and f"line {line}: PathWrap 'tri_long/" in msg and "--ignore PathWrap" in msg, msg
    data, info = read_osim(path, ignore=("PathWrap",))
    assert "tri_long" not in data.get("muscles", {}) and ("Thelen2003Muscle", "tri_long") in {
        (d["type"], d["name"]) for d in info["dropped"]}


def test_ellipsoid_quadrant_sharing_a_segment_is_refused(model, workdir):
    """A WrapEllipsoid with a quadrant and another PathWrap over one segment (its length
    is not stationary in its tangent points, so openfdk solves it alone): one line naming
    the muscle and ``--ignore PathWrap``."""
    import copy

    path = workdir / "shared_quadrant.osim"
    tree = etree.parse(str(model))
    _set(_wrap_object(tree, "condyle"), "quadrant", "+x")
    brach_set = _path_wrap(tree, "brach").getparent()
    brach_set.append(copy.deepcopy(_path_wrap(tree, "tri")))
    tree.write(str(path))
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert "\n" not in msg and path.name in msg and "'brach'" in msg and "--ignore PathWrap" in msg, msg
    assert "WrapEllipsoid with a quadrant and another PathWrap" in msg, msg


def test_torus_against_opensim(workdir):
    """A WrapTorus (tube radius 15 mm on a 60 mm circle) round the elbow, the path through
    its hole, at 30 random poses (wrapped and not). OpenSim places its cylinder at the
    azimuth of the root of its residual d/du[|a|² − 4R ρ] (WrapTorus.cpp, the line point
    nearest a circle of radius 2R); openfdk follows that rule: before it did (placing the
    cylinder at the circle point nearest the line) its length was 5.2e-5 relative longer
    than OpenSim's, because the length is not stationary in the placement (∂l/∂φ ≠ 0).
    Now: the length within 1e-5 relative of OpenSim's (8.4e-6 measured) and never longer
    (OpenSim's single PathWrap skips the cylinder's tangency step, opensim-core #3125, so
    its tangent points are not quite tangent and its path is longer, as for the cylinder);
    openfdk's moment arm is the derivative of its length (≤ 1e-8 m, the placement's
    dφ/dP term included) and non-zero; against −∂l/∂q of OpenSim's length ≤ 2e-5 m
    (1.1e-5 measured, the same non-tangency) and against ``computeMomentArm`` ≤ 1e-4 m
    (7.8e-5 measured: OpenSim's moment arm holds its tangent points fixed, without the
    placement's term)."""
    wraps = [("WrapTorus", "ring", "upper", (0.0, -0.3, 0.0), (1.5708, 0.0, 0.0), "all", (0.015, 0.06))]
    muscles = {"ringm": ([("o", "upper", (0.0, -0.1, 0.01)), ("i", "fore", (0.01, -0.1, 0.005))], [("ring", None)])}
    path = wrap_model(workdir / "torus.osim", wraps, muscles)
    d = compare(path, n=N_POSES, their_fd=True)["ringm"]
    print("torus", d)
    assert 0 < d["wrapped"] < N_POSES and d["dr_self"] <= 1e-8 and d["r_min"] > 1e-3
    assert d["dl"] <= 1e-5 and d["shorter"] <= 1e-12 and d["dr"] <= 1e-4 and d["dr_fd"] <= 2e-5


def test_inactive_wrap_object_is_left_out(model, workdir):
    """A wrap object with ``active`` false is left out, as OpenSim leaves it out: the
    PathWrap is listed as dropped and the length is OpenSim's (the straight path)."""
    path = workdir / "inactive.osim"
    _edit(model, path, lambda t: _set(_wrap_object(t, "head"), "active", "false"))
    data, info = read_osim(path)
    assert data["muscles"]["delt"]["path"] == ["ground.delt_o", "upper.delt_i"]
    assert any(d["type"] == "PathWrap" and d["name"].startswith("delt/") for d in info["dropped"])
    d = compare(path, n=8)["delt"]
    assert d["dl"] <= 1e-12


def test_import_opensim_file_keeps_the_wrapping(model, workdir):
    """``openfdk import-opensim`` writes the wrapping section (length, side, crossing_only,
    inside, one_segment); the written file loads to the same path lengths."""
    from openfdk.cli import main
    from openfdk.io.modelfile import load_model_and_settings

    out = workdir / "imported"
    assert main(["import-opensim", str(model), "--out", str(out)]) == 0
    written, _ = load_model_and_settings(out / "wrap_arm.yaml")
    data, _ = read_osim(model)
    direct = model_from_dict(data, source=str(model))
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = {"q_shoulder": float(rng.uniform(-1.5, 1.5)), "q_elbow": float(rng.uniform(-1.5, 1.5))}
        st_w, _ = pose_from_coordinates(written, q)
        st_d, _ = pose_from_coordinates(direct, q)
        for a, b in zip(written.muscles, direct.muscles):
            assert a.name == b.name
            la, lb = (float(np.ravel(m.path.evaluate(st, 0)[0])[0]) for m, st in ((a, st_w), (b, st_d)))
            assert abs(la - lb) <= 1e-12 * lb


if __name__ == "__main__":  # a report of the differences (python tests/test_opensim_wrapping.py [n])
    import sys
    import tempfile
    from pathlib import Path

    d = Path(tempfile.mkdtemp())
    p = wrap_model(d / "wrap_arm.osim")
    for name, rec in compare(p, n=int(sys.argv[1]) if len(sys.argv) > 1 else 30, exact=True).items():
        print(name, {k: f"{v:.1e}" if isinstance(v, float) else v for k, v in rec.items()})
