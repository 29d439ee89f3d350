"""openfdk view: the self-contained HTML viewer, opened in headless Chromium from a file
URL. Pixel positions are checked against a pinhole projection computed here from the
camera parameters passed in the URL and the body position read from kinematics.csv;
network use is checked in Chromium's NetLog and console log. Also: contact pressures in
the page data against the closed-form penetration of a sphere cap into a plane, the
decimation, bad input, and the file-size bound on a 60 s mandible trial."""

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from openfdk.cli import main
from openfdk.io.results import write_json, write_table
from openfdk.numerics.spatial import quat_from_matrix, quat_from_rotvec, rotation_matrix
from openfdk.viewer import ViewError, view_data, write_view
from openfdk.viewer.decimate import decimate
from openfdk.viewer.pack import unpack

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
HAVE_CHROMIUM = os.access(CHROMIUM, os.X_OK)
# .ci/run installs Chromium and sets OPENFDK_REQUIRE_BROWSER=1, so CI never skips these
needs_browser = pytest.mark.skipif(not HAVE_CHROMIUM and os.environ.get("OPENFDK_REQUIRE_BROWSER") != "1",
                                   reason="Debian package 'chromium' not installed (.ci/run installs it)")
FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run",
    "--no-pings", "--disable-domain-reliability", "--disable-default-apps", "--disable-extensions",
    "--enable-logging=stderr", "--v=0", "--virtual-time-budget=10000", "--hide-scrollbars",
]
BACKGROUND = np.array([243, 243, 241]) / 255.0


def browse(url, tmp, tag, size=(800, 600)):
    """Screenshot (H, W, 3) floats, console log text and the page-initiated network
    requests [(url, initiator)] of one headless Chromium visit."""
    shot, net = tmp / f"{tag}.png", tmp / f"{tag}-netlog.json"
    proc = subprocess.run(
        [CHROMIUM, *FLAGS, f"--user-data-dir={tmp / ('profile-' + tag)}", f"--log-net-log={net}",
         f"--window-size={size[0]},{size[1]}", f"--screenshot={shot}", url],
        capture_output=True, text=True, timeout=180)
    assert shot.is_file(), f"no screenshot; chromium said:\n{proc.stderr[-3000:]}"
    import matplotlib.image

    img = matplotlib.image.imread(shot)[..., :3].astype(float)
    return img, proc.stderr, page_requests(net)


def page_requests(netlog):
    """URL requests of the NetLog not started by the browser itself: the browser's own
    background requests carry the initiator 'not an origin'; a page's requests carry its
    origin (``null`` for a file:// page)."""
    data = json.loads(Path(netlog).read_text())
    url_request = data["constants"]["logSourceType"]["URL_REQUEST"]
    urls, initiators = {}, {}
    for ev in data["events"]:
        if ev["source"]["type"] != url_request:
            continue
        p, sid = ev.get("params", {}), ev["source"]["id"]
        if "url" in p:
            urls.setdefault(sid, p["url"])
        if "initiator" in p:
            initiators[sid] = p["initiator"]
    return [(u, initiators.get(sid)) for sid, u in urls.items() if initiators.get(sid) != "not an origin"]


def ready_info(log):
    m = re.findall(r'openfdk-view: ready (\{.*?\})", source', log)
    assert m, f"the viewer did not report ready; console:\n{_console(log)}"
    return json.loads(m[-1])


def camera_info(log):
    """The page's camera as last reported: at ready, updated by the last resize (the
    headless window is resized to the screenshot size after load)."""
    info = ready_info(log)
    sizes = re.findall(r'openfdk-view: size \d+ \d+ (\{.*?\})", source', log)
    if sizes:
        info.update(json.loads(sizes[-1]))
    return info


def _console(log):
    return "\n".join(line for line in log.splitlines() if "CONSOLE" in line)[-3000:]


def project(p_W, eye, target, up, fov_deg, width, height):
    """Pixel (x right, y down) of world point p_W seen by a pinhole camera at ``eye``
    looking at ``target`` (vertical field of view fov_deg, image width × height)."""
    f = (target - eye) / np.linalg.norm(target - eye)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    d = p_W - eye
    x, y, z = d @ r, d @ u, d @ f
    t = np.tan(np.radians(fov_deg) / 2)
    ndc = np.array([x / (z * t * width / height), y / (z * t)])
    return np.array([(ndc[0] + 1) / 2 * width, (1 - ndc[1]) / 2 * height])


def magenta_centroid(img):
    mask = (img[..., 0] > 0.9) & (img[..., 1] < 0.1) & (img[..., 2] > 0.9)
    assert mask.sum() > 20, "the probe body (magenta) is not in the picture"
    ys, xs = np.nonzero(mask)
    return np.array([xs.mean(), ys.mean()]) + 0.5, mask  # pixel k covers [k, k + 1)


# -- a small run: the slider-crank example ----------------------------------------------------
@pytest.fixture(scope="module")
def slider_view(tmp_path_factory):
    d = tmp_path_factory.mktemp("view-sc")
    assert main(["run", str(ROOT / "examples" / "slider_crank.yaml"), "--out", str(d / "run"), "--no-progress"]) == 0
    assert main(["view", str(d / "run")]) == 0
    return d


def test_run_records_the_absolute_model_path_and_view_finds_it(slider_view):
    s = json.loads((slider_view / "run" / "summary.json").read_text())
    assert Path(s["input"]["model_file"]) == (ROOT / "examples" / "slider_crank.yaml").resolve()
    html = (slider_view / "run" / "view.html").read_text()
    assert "<script src" not in html and "http://" not in html.split("three-core")[0]
    lic = (ROOT / "src" / "openfdk" / "viewer" / "vendor" / "LICENSE-three.txt").read_text()
    assert lic in html and "three.js authors" in lic  # the vendored licence travels with the code, verbatim


def test_a_kinematics_only_result_can_be_viewed(slider_view, tmp_path):
    out = tmp_path / "kin"
    assert main(["kinematics", str(ROOT / "examples" / "slider_crank.yaml"), "--out", str(out), "--no-progress"]) == 0
    data, _ = view_data(out)
    assert data["frames"]["measured"] is None and data["frames"]["contacts"] == []
    poses = unpack(data["frames"]["poses"])
    names = [b["name"] for b in data["scene"]["bodies"]]
    # the crank turns once per second about the ground pivot: its centre of mass at t = 0.25 s
    np.testing.assert_allclose(poses[25, names.index("crank"), :3], [0.0, 0.05, 0.0], atol=1e-6)


@needs_browser
def test_browser_draws_the_body_at_its_projected_position_at_two_times(slider_view, tmp_path):
    import csv

    with open(slider_view / "run" / "kinematics.csv") as fh:
        rows = list(csv.DictReader(fh))
    kin = {k: np.array([float(r[k]) for r in rows]) for k in ("time", "slider.x_m", "slider.y_m", "slider.z_m")}
    eye, target, up, fov = np.array([0.05, 0.35, 0.8]), np.array([0.3, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 40.0
    cam = ",".join(f"{v:g}" for v in (*eye, *target))
    url = (slider_view / "run" / "view.html").as_uri()
    shots = {}
    for t in (0.0, 0.5):
        img, log, requests = browse(f"{url}#t={t}&cam={cam}&fov={fov:g}&ui=0&probe=slider", tmp_path, f"t{t}")
        info = ready_info(log)
        assert "Content Security Policy" not in log and "openfdk-view: error" not in log, _console(log)
        assert requests == [], f"the page made network requests: {requests}"
        h, w = img.shape[:2]
        sizes = re.findall(r"openfdk-view: size (\d+) (\d+)", log)
        assert (w, h) == tuple(int(v) for v in (sizes[-1] if sizes else (info["width"], info["height"])))
        k = int(np.argmin(np.abs(kin["time"] - t)))
        assert info["frame"] == k
        p_W = np.array([kin["slider.x_m"][k], kin["slider.y_m"][k], kin["slider.z_m"][k]])
        expected = project(p_W, eye, target, up, fov, w, h)
        centroid, mask = magenta_centroid(img)
        assert np.linalg.norm(centroid - expected) < 1.5, (centroid, expected)  # measured: ≤ 0.12 px
        # not blank: besides the probe, other bodies' frames are drawn
        other = np.any(np.abs(img - BACKGROUND) > 0.08, axis=2) & ~mask
        assert other.sum() > 200
        shots[t] = (img, expected)
    (a, pa), (b, pb) = shots[0.0], shots[0.5]
    assert np.linalg.norm(pa - pb) > 100  # the slider moved 0.2 m: far apart in the picture
    for p in (pa, pb):  # the pictures differ where the slider was and where it went
        x, y = int(round(p[0])), int(round(p[1]))
        assert np.abs(a[y - 5 : y + 6, x - 5 : x + 6] - b[y - 5 : y + 6, x - 5 : x + 6]).max() > 0.5
    assert np.array_equal(a[:40, :40], b[:40, :40])  # a corner with nothing moving is the same


@needs_browser
def test_network_check_sees_a_page_request(tmp_path):
    """The NetLog check above would see a request made by a file:// page."""
    page = tmp_path / "probe.html"
    page.write_text('<html><body><img src="http://127.0.0.1:9/x.png"></body></html>')
    _img, _log, requests = browse(page.as_uri(), tmp_path, "probe")
    assert any(u.startswith("http://127.0.0.1:9/") for u, _ in requests)


# -- the TMJ-like FDK model: contact, ligaments, muscles, springs, markers, visual mesh -------
def write_jaw_result(d, n_frames, rate=100.0, visual_subdivisions=3, offset=(0.0, 0.0, 0.0)):
    """A result folder for the TMJ-like FDK model (openfdk.fixtures.synthetic_jaw) whose poses are
    the model's known open–close motion (both bodies moved by ``offset`` m, as in a lab-frame
    trial), plus known forces; returns (folder, model path)."""
    import trimesh

    from openfdk.fixtures.synthetic_jaw import jaw_fdk_model_dict, jaw_true_motion, write_jaw_meshes

    write_jaw_meshes(d / "meshes")
    trimesh.creation.icosphere(subdivisions=visual_subdivisions, radius=12.0).export(d / "meshes" / "chin.stl")
    data = jaw_fdk_model_dict("meshes")
    data["bodies"]["mandible"]["visual"] = {"mesh": "meshes/chin.stl", "units": "mm", "color": "#c8b89a",
                                            "placement": {"position": [70, 0, -10]}}
    (d / "tmj.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    t = np.arange(n_frames) / rate
    poses = jaw_true_motion(t)  # body origins: the skull's, the mandible's centre of mass
    cols = {"time": t, "converged": np.ones(n_frames, int)}
    for body in ("skull", "mandible"):
        p, R = poses[body]
        q = np.array([quat_from_matrix(r) for r in R])
        for j, c in enumerate("xyz"):
            cols[f"{body}.{c}_m"] = p[:, j] + offset[j]
        for j in range(4):
            cols[f"{body}.e{j}"] = q[:, j]
    for m in ("S1", "S2", "S3", "S4", "J1", "J2", "J3", "J4"):
        for j, c in enumerate("xyz"):
            cols[f"{m}.residual_{c}_m"] = np.full(n_frames, 5e-4 if c == "x" else 0.0)
    cols["message"] = [""] * n_frames
    for key in cols:  # frame 3 failed: no pose, no residuals (as openfdk writes a failed frame)
        if key.startswith(("skull.", "mandible.", "S", "J")):
            cols[key][3] = np.nan
    cols["converged"][3] = 0
    cols["message"][3] = "frame 3 (t = 0.0300 s): test failure"
    out = d / "run"
    out.mkdir()
    write_table(out / "kinematics.csv", cols)
    from openfdk.io.modelfile import load_model

    model = load_model(d / "tmj.yaml")
    f = {"time": t, "converged": np.ones(n_frames, int)}
    for k, el in enumerate(model.muscles):
        f[f"{el.name}.force_N"] = 10.0 * (k + 1) * (1 + np.sin(2 * np.pi * t))
    for el in model.ligaments:
        f[f"{el.name}.force_N"] = np.full(n_frames, 2.0)
    for el in model.springs:
        f[f"{el.name}.force"] = np.full(n_frames, 0.001)
    for c in model.contacts:
        for a, v in zip("xyz", (0.0, 0.0, -50.0)):
            f[f"{c.name}.F{a}_N"] = np.full(n_frames, v)
            f[f"{c.name}.cop_{a}_m"] = np.full(n_frames, offset["xyz".index(a)])
    for dof in model.fdk_dofs:
        f[f"fdk.{dof.name}.alpha"] = np.full(n_frames, 1e-4)
        f[f"fdk.{dof.name}.residual"] = np.full(n_frames, 1e-6)
    f["fdk_converged"] = np.ones(n_frames, int)
    f["message"] = [""] * n_frames
    write_table(out / "forces.csv", f)
    write_json(out / "summary.json", {"input": {"model": "tmj.yaml", "trial": "trial.c3d"}})
    return out, d / "tmj.yaml"


@pytest.fixture(scope="module")
def jaw_result(tmp_path_factory):
    return write_jaw_result(tmp_path_factory.mktemp("view-jaw"), 12)


def test_contact_pressure_in_the_page_data_matches_the_closed_form(jaw_result):
    """Each condyle (sphere cap, 1 mm cartilage offset) presses into its fossa plane:
    a vertex at signed height h above the plane carries p = k h (elastic foundation,
    k = 10 GN/m³). The page stores the pressure on the display vertices, quantised to
    255 levels of the trial's peak; decoded, it must equal k h to the quantum plus the
    distance-grid error."""
    from openfdk.fixtures.synthetic_jaw import plane_normal

    out, model_path = jaw_result
    data, _ = view_data(out)
    scene, frames = data["scene"], data["frames"]
    poses = unpack(frames["poses"])
    names = [b["name"] for b in scene["bodies"]]
    skull, jaw = names.index("skull"), names.index("mandible")
    k_p = 1.0e10
    for side, c_scene, c_frames in zip((-1, 1), scene["contacts"], frames["contacts"]):
        mesh = scene["meshes"][c_scene["mesh"]]
        v_B = unpack(mesh["vertices"]).reshape(-1, 3)
        offsets, index, level = unpack(c_frames["offsets"]), unpack(c_frames["index"]), unpack(c_frames["level"])
        n_S = plane_normal(side)  # plane normal in the skull frame, pointing into the skull
        top_S = np.array([0.0, side * 0.0495, 0.0])
        h_all = []
        for f in range(len(poses)):
            if f == 3:  # the failed frame: nothing drawn
                assert offsets[4] == offsets[3] and np.isnan(poses[3, jaw]).all()
                h_all.append(np.full(len(v_B), -1.0))
                continue
            qs, qm = poses[f, skull].astype(float), poses[f, jaw].astype(float)
            R_s, R_m = rotation_matrix(qs[3:]), rotation_matrix(qm[3:])
            v_S = (qm[:3] + v_B @ R_m.T - qs[:3]) @ R_s  # vertices in the skull frame
            h_all.append((v_S - top_S) @ n_S)
        p_max = k_p * max(h.max() for h in h_all)
        assert c_frames["p_max"] == pytest.approx(p_max, rel=0.02)
        for f, h in enumerate(h_all):
            if f == 3:
                continue
            idx, lev = index[offsets[f] : offsets[f + 1]], level[offsets[f] : offsets[f + 1]]
            p = lev / 255.0 * c_frames["p_max"]
            assert len(idx) > 0
            np.testing.assert_allclose(p, k_p * h[idx], atol=c_frames["p_max"] / 255 + k_p * 3e-5)
            outside = np.setdiff1d(np.arange(len(h)), idx)
            assert np.all(h[outside] < 3e-5)  # vertices not stored are not in contact


def test_view_data_rebuilds_markers_paths_and_panel(jaw_result):
    out, _ = jaw_result
    data, _ = view_data(out)
    scene, frames = data["scene"], data["frames"]
    assert [m["kind"] for m in scene["meshes"]] == ["contact"] * 4 + ["visual"]
    chin = unpack(scene["meshes"][4]["vertices"]).reshape(-1, 3)  # icosphere r = 12 mm placed at (70, 0, -10) mm
    assert scene["meshes"][4]["body"] == [b["name"] for b in scene["bodies"]].index("mandible")
    np.testing.assert_allclose(np.linalg.norm(chin - [0.07, 0.0, -0.01], axis=1), 0.012, rtol=1e-6)
    assert {p["kind"] for p in scene["paths"]} == {"muscle", "ligament"}  # FDK springs act on non-path measures
    assert len(scene["paths"]) == 24 + 6
    # measured = model marker − residual (residual 0.5 mm along x)
    poses, meas = unpack(frames["poses"]), unpack(frames["measured"])
    j = scene["markers"]["names"].index("J2")
    b, p_B = scene["markers"]["body"][j], np.array(scene["markers"]["p_B"][j])
    q = poses[5, b].astype(float)
    np.testing.assert_allclose(meas[5, j], q[:3] + rotation_matrix(q[3:]) @ p_B - [5e-4, 0, 0], atol=1e-6)
    assert np.isnan(meas[3]).all()
    assert frames["failed"] == [(3, "frame 3 (t = 0.0300 s): test failure")]
    names = [s["name"] for s in frames["panel"]]
    assert "tmj_r_normal α" in names and "marker RMS residual" in names
    assert "spring fdk_spring_ml" in names  # a spring on a non-path measure: in the panel
    np.testing.assert_allclose(unpack(frames["panel"][names.index("spring fdk_spring_ml")]["values"]), 0.001)
    rms = unpack(frames["panel"][names.index("marker RMS residual")]["values"])
    np.testing.assert_allclose(np.delete(rms, 3), 0.5, rtol=1e-5)  # mm
    assert np.isnan(rms[3])


def test_a_window_of_the_run_holds_its_frames_and_nothing_else(jaw_result, capsys):
    """`openfdk view --start --end`: one cycle of a long trial. The window's frames are the
    whole run's, value for value, and a window with no frame is one line."""
    out, _ = jaw_result
    whole, _ = view_data(out)
    part, _ = view_data(out, start=0.02, end=0.065)
    t_all, t = unpack(whole["frames"]["time"]), unpack(part["frames"]["time"])
    keep = (t_all >= 0.02 - 1e-9) & (t_all <= 0.065 + 1e-9)
    assert keep.sum() == 5 and len(t) == 5
    np.testing.assert_array_equal(t, t_all[keep])
    np.testing.assert_array_equal(unpack(part["frames"]["poses"]), unpack(whole["frames"]["poses"])[keep])
    # the failed frame 3 (0.03 s) is the window's second
    assert part["frames"]["failed"] == [(1, "frame 3 (t = 0.0300 s): test failure")]
    assert "5 frames, t = 0.020 … 0.060 s" in part["meta"]["lines"]
    code = main(["view", str(out), "--start", "5", "--end", "6", "--out", str(out / "w.html")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no frame within [5, 6] s (the run covers 0–0.11 s)" in err[0], err
    assert not (out / "w.html").exists()


@needs_browser
def test_browser_shows_the_fdk_jaw_without_errors(jaw_result, tmp_path):
    out, _ = jaw_result
    page = write_view(out, tmp_path / "jaw.html")
    img, log, requests = browse(f"{page.as_uri()}#frame=3&view=anterior", tmp_path, "jaw", size=(900, 700))
    info = ready_info(log)
    assert "openfdk-view: error" not in log and "Content Security Policy" not in log, _console(log)
    assert requests == []
    assert (info["meshes"], info["markers"], info["paths"], info["contacts"]) == (5, 8, 30, 2)
    # the failed frame is announced in the banner (red text) and the canvas is drawn
    red = (img[..., 0] > 0.6) & (img[..., 1] < 0.2) & (img[..., 2] < 0.25)
    assert red.sum() > 30
    assert np.any(np.abs(img - BACKGROUND) > 0.08, axis=2).mean() > 0.02


# -- framing: a lab-frame trial (the bodies ~1.2 m from the origin) --------------------------
LAB_OFFSET = (0.30, 0.20, 1.15)


@pytest.fixture(scope="module")
def lab_result(tmp_path_factory):
    return write_jaw_result(tmp_path_factory.mktemp("view-lab"), 12, offset=LAB_OFFSET)


def _body_points_W(scene, poses, f):
    """World points (k, 3) m of the moving bodies at frame f: origins, named points, mesh
    vertices, model markers, path points."""
    pts = []
    for i in range(len(scene["bodies"])):
        if scene["bodies"][i]["fixed"]:  # the ground, at the origin: not what is framed
            continue
        q = poses[f, i].astype(float)
        p_B = [np.zeros((1, 3))] + [unpack(m["vertices"]).reshape(-1, 3) for m in scene["meshes"] if m["body"] == i]
        p_B += [np.array([p]) for b, p in zip(scene["markers"]["body"], scene["markers"]["p_B"]) if b == i]
        p_B += [np.array(scene["bodies"][i]["points"]).reshape(-1, 3)]
        p_B += [np.array([a[1:]]) for path in scene["paths"] for a in path["points"] if a[0] == i]
        pts.append(q[:3] + np.concatenate(p_B) @ rotation_matrix(q[3:]).T)
    return np.concatenate(pts)


def test_bounds_hold_the_motion_over_all_frames_and_skip_failed_ones(lab_result):
    out, _ = lab_result
    data, _ = view_data(out)
    scene, frames = data["scene"], data["frames"]
    poses = unpack(frames["poses"])
    lo, hi = np.array(frames["bounds"]["min"]), np.array(frames["bounds"]["max"])
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))  # frame 3 (NaN poses) is skipped
    every = np.concatenate([_body_points_W(scene, poses, f) for f in range(len(poses)) if f != 3])
    every = np.concatenate([every, unpack(frames["measured"]).reshape(-1, 3)])
    every = every[np.all(np.isfinite(every), axis=1)]
    # the box is the box of all the geometry (extreme points of each body: exact on the axes' extremes
    # up to the 50-direction sampling of the rotated meshes, here < 1 mm)
    np.testing.assert_allclose(lo, every.min(0), atol=1e-3)
    np.testing.assert_allclose(hi, every.max(0), atol=1e-3)
    # it is around the lab-frame position, not the model's reference pose near the origin
    assert np.linalg.norm(0.5 * (lo + hi) - LAB_OFFSET) < 0.06
    assert np.linalg.norm(np.array(scene["center"]) - LAB_OFFSET) > 1.0


def _coverage(info, pts, w, h):
    """Fraction of the free canvas (info["visible"]) covered by the projected bounding box of
    ``pts`` seen by the page's camera (view offset included), and the box (x0, y0, x1, y1)."""
    eye, target, up = (np.array(info[k]) for k in ("eye", "target", "up"))
    xy = np.array([project(p, eye, target, up, info["fov"], w, h) for p in pts]) - np.array(info["offset"])
    x0, y0 = xy.min(0)
    x1, y1 = xy.max(0)
    vx0, vy0, vx1, vy1 = info["visible"]
    inter = max(0.0, min(x1, vx1) - max(x0, vx0)) * max(0.0, min(y1, vy1) - max(y0, vy0))
    return inter / ((vx1 - vx0) * (vy1 - vy0)), (x0, y0, x1, y1)


@needs_browser
@pytest.mark.parametrize("view", ["", "anterior", "left", "superior"])
def test_browser_frames_a_lab_frame_trial_in_the_canvas_outside_the_panel(lab_result, tmp_path, view):
    """At the first frame and mid-trial, the projected box of the bodies covers ≥ 30 % of
    the canvas the side panel leaves free, and lies inside it (the default view and the
    presets). The projection is checked against the pixels: the mandible's origin (probe
    disc) is drawn where the camera reported by the page puts it."""
    out, _ = lab_result
    page = write_view(out, tmp_path / "lab.html")
    data, _ = view_data(out)
    poses = unpack(data["frames"]["poses"])
    names = [b["name"] for b in data["scene"]["bodies"]]
    for frame in (0, 6):
        tag = f"lab-{view or 'default'}-{frame}"
        img, log, requests = browse(f"{page.as_uri()}#frame={frame}&probe=mandible" + (f"&view={view}" if view else ""),
                                    tmp_path, tag, size=(1000, 700))
        info = camera_info(log)
        assert "openfdk-view: error" not in log and requests == [], _console(log)
        h, w = img.shape[:2]
        vx0, vy0, vx1, vy1 = info["visible"]
        assert vx1 < w - 250 and (vx0, vy0, vy1) == (0, 0, h)  # the panel (right) is not free canvas
        cover, (x0, y0, x1, y1) = _coverage(info, _body_points_W(data["scene"], poses, frame), w, h)
        assert cover >= 0.30, (cover, (x0, y0, x1, y1), info["visible"])
        assert x0 >= vx0 - 1 and x1 <= vx1 + 1 and y0 >= -1 and y1 <= h + 1, ((x0, y0, x1, y1), info["visible"])
        q = poses[frame, names.index("mandible")].astype(float)
        expected = _coverage(info, [q[:3]], w, h)[1][:2]
        centroid, _mask = magenta_centroid(img)
        assert np.linalg.norm(centroid - expected) < 2.0, (centroid, expected)


@needs_browser
def test_browser_fit_key_frames_the_motion_again(lab_result, tmp_path):
    """A camera aimed elsewhere (cam=…) is brought back on the motion by the F key
    (fit=1 in the URL presses it once the page is ready)."""
    out, _ = lab_result
    page = write_view(out, tmp_path / "lab.html")
    data, _ = view_data(out)
    poses = unpack(data["frames"]["poses"])
    img, log, _ = browse(f"{page.as_uri()}#frame=0&cam=3,3,3,-2,-2,-2&fit=1", tmp_path, "lab-fit", size=(1000, 700))
    info = camera_info(log)
    cover, _box = _coverage(info, _body_points_W(data["scene"], poses, 0), img.shape[1], img.shape[0])
    assert cover >= 0.30
    d = np.array(info["eye"]) - np.array(info["target"])  # the direction of view is kept
    np.testing.assert_allclose(d / np.linalg.norm(d), np.ones(3) / np.sqrt(3), atol=1e-6)


# -- colours and force-arrow scale ------------------------------------------------------------
def _neutral(hex_colour):
    r, g, b = (int(hex_colour[i:i + 2], 16) for i in (1, 3, 5))
    return max(r, g, b) - min(r, g, b) <= 4


def test_body_colours_are_neutral_greys_and_the_contact_arrow_scale_is_packed(lab_result):
    out, _ = lab_result
    data, _ = view_data(out)
    assert all(_neutral(b["color"]) for b in data["scene"]["bodies"])
    sc = data["frames"]["arrow_scale"]
    assert sc["grf"] is None  # no grf.csv
    assert sc["contact"]["fmax"] == pytest.approx(50.0)  # |(0, 0, -50)| N, every frame
    assert sc["contact"]["length_m"] == pytest.approx(0.35 * data["scene"]["scale"])


@needs_browser
def test_browser_draws_sticks_in_grey(slider_view, tmp_path):
    """The slider-crank bodies have no meshes: a stick from each origin to each of its
    points. Near each stick's middle, the darkest pixel is grey (no hue)."""
    data, _ = view_data(slider_view / "run")
    poses = unpack(data["frames"]["poses"])
    eye, target, up, fov = np.array([0.05, 0.35, 0.8]), np.array([0.3, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 40.0
    cam = ",".join(f"{v:g}" for v in (*eye, *target))
    url = (slider_view / "run" / "view.html").as_uri()
    img, log, _ = browse(f"{url}#frame=0&cam={cam}&fov={fov:g}&ui=0", tmp_path, "sticks")
    h, w = img.shape[:2]
    checked = 0
    for i, b in enumerate(data["scene"]["bodies"]):
        q = poses[0, i].astype(float)
        for p_B in b["points"]:
            mid = q[:3] + rotation_matrix(q[3:]) @ (0.5 * np.array(p_B))
            x, y = project(mid, eye, target, up, fov, w, h).astype(int)
            if not (3 <= x < w - 3 and 3 <= y < h - 3) or np.linalg.norm(p_B) < 0.02:
                continue
            patch = img[y - 2:y + 3, x - 2:x + 3].reshape(-1, 3)
            px = patch[np.argmin(patch.sum(axis=1))]
            assert np.all(BACKGROUND - px > 0.1), (b["name"], px)  # a line is there
            assert np.ptp(px) < 0.06, (b["name"], px)  # and it is grey
            checked += 1
    assert checked >= 2


@needs_browser
def test_browser_contact_arrow_has_its_scale_in_the_legend(lab_result, tmp_path):
    """The legend gives the contact arrow's scale (length = force); the arrow head is drawn
    where that scale puts it: 0.85 of the length from the centre of pressure, along F."""
    out, _ = lab_result
    page = write_view(out, tmp_path / "lab.html")
    data, _ = view_data(out)
    sc = data["frames"]["arrow_scale"]["contact"]
    img, log, _ = browse(f"{page.as_uri()}#frame=0&view=anterior&hide=frames,meshes,markers,paths", tmp_path,
                         "arrow", size=(1000, 700))
    info = camera_info(log)
    assert f"{sc['length_m'] * 1e3:.3g} mm = 50.0 N" in info["legend"]
    h, w = img.shape[:2]
    cop = np.array(LAB_OFFSET)
    head = cop + 0.85 * sc["length_m"] * np.array([0.0, 0.0, -1.0])  # F = (0, 0, -50) N = fmax
    x, y = _coverage(info, [head], w, h)[1][:2]
    patch = img[int(y) - 2:int(y) + 3, int(x) - 2:int(x) + 3].reshape(-1, 3)
    red = (patch[:, 0] > 0.5) & (patch[:, 1] < 0.25) & (patch[:, 2] < 0.25)
    assert red.sum() >= 5, patch
    beyond = cop + 1.2 * sc["length_m"] * np.array([0.0, 0.0, -1.0])  # past the tip: no arrow
    x, y = _coverage(info, [beyond], w, h)[1][:2]
    patch = img[int(y) - 2:int(y) + 3, int(x) - 2:int(x) + 3].reshape(-1, 3)
    assert not np.any((patch[:, 0] > 0.5) & (patch[:, 1] < 0.25) & (patch[:, 2] < 0.25)), patch


# -- muscles and ligaments as tubes, width by strength, name and force on hover ----------------
def test_path_tube_radius_grows_with_strength(lab_result):
    from openfdk.io.modelfile import load_model
    from openfdk.viewer.scene import TUBE_RADIUS

    out, model_path = lab_result
    data, _ = view_data(out)
    paths, scale = data["scene"]["paths"], data["scene"]["scale"]
    model = load_model(model_path)
    f0 = {m.name: m.law.max_isometric_force for m in model.muscles}
    k = {g.name: g.law.stiffness for g in model.ligaments}
    lo, hi = TUBE_RADIUS
    for kind, strength, unit in (("muscle", f0, "N"), ("ligament", k, "N/m")):
        top = max(strength.values())
        for p in (p for p in paths if p["kind"] == kind):
            assert p["strength"] == pytest.approx(strength[p["name"]]) and p["strength_unit"] == unit
            frac = np.sqrt(strength[p["name"]] / top)
            assert p["radius_m"] == pytest.approx(scale * (lo + (hi - lo) * frac))
    radii = [p["radius_m"] for p in paths if p["kind"] == "muscle"]
    assert max(radii) > 1.5 * min(radii)  # the jaw muscles differ in strength: so do the tubes


def _segments_px(info, scene, poses, f, w, h):
    """[(path index, a_px, b_px, a_W, b_W)] of every straight path segment at frame f."""
    out = []
    for j, p in enumerate(scene["paths"]):
        pts = []
        for a in p["points"]:
            q = poses[f, a[0]].astype(float)
            pts.append(q[:3] + rotation_matrix(q[3:]) @ np.array(a[1:]))
        for a, b in zip(pts[:-1], pts[1:]):
            out.append((j, *(_coverage(info, [x], w, h)[1][:2] for x in (a, b)), a, b))
    return [(j, np.array(a), np.array(b), aw, bw) for j, a, b, aw, bw in out]


def _dist_to_segment(x, a, b):
    t = np.clip((x - a) @ (b - a) / max((b - a) @ (b - a), 1e-12), 0, 1)
    return np.linalg.norm(x - (a + t * (b - a)))


@needs_browser
def test_browser_hover_names_the_muscle_and_its_force_and_tubes_are_wide(lab_result, tmp_path):
    out, _ = lab_result
    page = write_view(out, tmp_path / "lab.html")
    data, _ = view_data(out)
    scene, poses = data["scene"], unpack(data["frames"]["poses"])
    img, log, _ = browse(f"{page.as_uri()}#frame=0&view=left", tmp_path, "tubes", size=(1000, 700))
    info = camera_info(log)
    h, w = img.shape[:2]
    segs = _segments_px(info, scene, poses, 0, w, h)
    vx1 = info["visible"][2]
    best = None  # the midpoint of a muscle segment farthest from every other path's segments
    for j, a, b, aw, bw in segs:
        mid = 0.5 * (a + b)
        if scene["paths"][j]["kind"] != "muscle" or not (60 < mid[0] < vx1 - 20 and 90 < mid[1] < h - 160):
            continue
        clear = min((_dist_to_segment(mid, a2, b2) for j2, a2, b2, _, _ in segs if j2 != j), default=1e9)
        if best is None or clear > best[0]:
            best = (clear, j, mid, a, b, aw, bw)
    clear, j, mid, a, b, aw, bw = best
    assert clear > 8, best
    # the tube's width on screen: its projected diameter (±40 %, ≥ 3 px)
    eye = np.array(info["eye"])
    depth = np.linalg.norm(0.5 * (aw + bw) - eye)
    f_px = 0.5 * h / np.tan(np.radians(info["fov"]) / 2)
    expected = 2 * scene["paths"][j]["radius_m"] * f_px / depth
    n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
    along = [img[int(round(y)), int(round(x))] for x, y in (mid + t * n for t in np.arange(-15, 15.5, 0.5))]
    width = 0.5 * sum(np.abs(px - BACKGROUND).max() > 0.1 for px in along)
    assert width >= 3 and abs(width - expected) < 0.4 * expected + 1.5, (width, expected)
    # hovering the middle of the tube names the muscle and its force at this frame
    _img, log, _ = browse(f"{page.as_uri()}#frame=0&view=left&hover={mid[0]:.1f},{mid[1]:.1f}", tmp_path,
                          "hover", size=(1000, 700))
    assert camera_info(log)["eye"] == pytest.approx(info["eye"])
    hov = json.loads(re.findall(r'openfdk-view: hover (\{.*?\})", source', log)[-1])
    name = scene["paths"][j]["name"]
    force = unpack(data["frames"]["path_force"])[0, j]
    assert hov["hit"]["name"] == name and hov["hit"]["force"] == pytest.approx(force, rel=1e-6)
    m = re.fullmatch(rf"{name} \(muscle\): ([-0-9.e+]+) N; strength ([0-9.e+]+) N", hov["tip"])
    assert m, hov["tip"]
    assert float(m.group(1)) == pytest.approx(force, rel=1e-3)
    assert float(m.group(2)) == pytest.approx(scene["paths"][j]["strength"], rel=1e-2)


# -- mesh decimation ----------------------------------------------------------------------------
def test_decimation_bounds_vertices_and_keeps_the_shape():
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=6, radius=0.02)  # 40 962 vertices
    v, f, labels = decimate(sphere.vertices, sphere.faces, 2000)
    assert len(v) <= 2000 and len(f) > 1000
    assert labels.shape == (len(sphere.vertices),) and labels.max() == len(v) - 1
    r = np.linalg.norm(v, axis=1)
    assert np.all(np.abs(r - 0.02) < 0.0015)  # cluster means stay near the surface
    assert np.all(np.linalg.norm(sphere.vertices - v[labels], axis=1) < 0.003)
    v2, f2, l2 = decimate(sphere.vertices, sphere.faces, 10**6)
    assert len(v2) == len(sphere.vertices) and np.array_equal(l2, np.arange(len(v2)))


# -- bad input: one line, exit 2 ----------------------------------------------------------------
def test_bad_inputs_exit_2_with_one_line(tmp_path, capsys, jaw_result):
    assert main(["view", str(tmp_path / "nothing")]) == 2
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["view", str(tmp_path / "empty")]) == 2
    assert "kinematics.csv: missing" in capsys.readouterr().err
    out, model_path = jaw_result
    bad = tmp_path / "bad"
    shutil.copytree(out, bad)
    write_json(bad / "summary.json", {"input": {"model": "/no/such/model.yaml"}})
    assert main(["view", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "summary.json: input.model" in err and err.count("\n") == 1
    data = yaml.safe_load(model_path.read_text())
    data["bodies"]["mandible"]["visual"] = {"mesh": "meshes/missing.stl"}
    (model_path.parent / "bad.yaml").write_text(yaml.safe_dump(data))
    assert main(["view", str(out), "--model", str(model_path.parent / "bad.yaml")]) == 2
    assert "bodies.mandible.visual.mesh: mesh file" in capsys.readouterr().err
    data["bodies"]["mandible"]["visual"] = {"mesh": "meshes/chin.stl", "colour": "#ffffff"}
    (model_path.parent / "bad.yaml").write_text(yaml.safe_dump(data))
    assert main(["check", str(model_path.parent / "bad.yaml")]) == 2
    assert "bodies.mandible.visual.colour: unknown key" in capsys.readouterr().err


# -- size: a 60 s trial of the mandible FDK model ----------------------------------------------
def test_a_60_s_mandible_trial_gives_a_file_under_30_MB(tmp_path):
    """The virtual subject's FDK model (default-resolution meshes), 60 s at 100 Hz: the
    mandible opens and closes (8° about the intercondylar axis, 1 Hz) so that the
    condyles press into the fossae; every frame's contact is evaluated and stored."""
    from openfdk.mandible.experiment import record_experiment
    from openfdk.mandible.generator import create_subject
    from openfdk.mandible.models import write_models
    from openfdk.mandible.registration import register_braces
    from openfdk.mandible.subject import load_subject
    from openfdk.io.modelfile import load_model

    subject_dir = create_subject(tmp_path / "subject", resolution="default")
    record_experiment(subject_dir, cycles=1)
    subject = load_subject(subject_dir)
    models = write_models(subject, register_braces(subject, Path(subject_dir) / "trials" / "reference.c3d"),
                          tmp_path / "models")
    model = load_model(models["fdk"])
    # lift the mandible until both condyles touch their fossae (+0.3 mm), so that contact is drawn
    jaw, skull = model.body("mandible"), model.body("skull")

    def touching(dz):
        R_j, R_s = rotation_matrix(jaw.quat_WB0), rotation_matrix(skull.quat_WB0)
        return all(c.pair.evaluate(jaw.p_WB0 + [0, 0, dz], R_j, skull.p_WB0, R_s).n_contact > 0
                   for c in model.contacts)

    lift = next(dz for dz in np.arange(0.0, 0.01, 1e-4) if touching(dz)) + 3e-4
    n = 6000
    t = np.arange(n) / 100.0
    cols = {"time": t, "converged": np.ones(n, int)}
    for b in model.moving_bodies:
        p0, R0 = b.p_WB0, rotation_matrix(b.quat_WB0)
        if b.name == "mandible":  # rotation about the intercondylar (y) axis through the origin
            th = np.radians(8.0) * 0.5 * (1 - np.cos(2 * np.pi * t))
            R = np.array([rotation_matrix(quat_from_rotvec([0.0, a, 0.0])) for a in th])
            p = np.einsum("fij,j->fi", R, p0) + [0.0, 0.0, lift]
            q = np.array([quat_from_matrix(r @ R0) for r in R])
        else:
            p, q = np.tile(p0, (n, 1)), np.tile(b.quat_WB0, (n, 1))
        for j, c in enumerate("xyz"):
            cols[f"{b.name}.{c}_m"] = p[:, j]
        for j in range(4):
            cols[f"{b.name}.e{j}"] = q[:, j]
    for m in model.markers.names:
        for c in "xyz":
            cols[f"{m}.residual_{c}_m"] = 1e-4 * np.sin(t)
    out = tmp_path / "run"
    out.mkdir()
    write_table(out / "kinematics.csv", cols)
    f = {"time": t, "converged": np.ones(n, int)}
    for el in model.muscles + model.ligaments:
        f[f"{el.name}.force_N"] = 100 * np.sin(t) ** 2
    for dof in model.fdk_dofs:
        f[f"fdk.{dof.name}.alpha"] = 1e-4 * np.sin(t)
        f[f"fdk.{dof.name}.residual"] = 1e-3 * np.cos(t)
    f["fdk_converged"] = np.ones(n, int)
    write_table(out / "forces.csv", f)
    write_json(out / "summary.json", {"input": {"model_file": str(Path(models["fdk"]).resolve())}})
    from openfdk.viewer.page import render_page

    data, title = view_data(out)
    page = out / "view.html"
    page.write_text(render_page(data, title), encoding="utf-8")
    levels = sum(len(unpack(c["level"])) for c in data["frames"]["contacts"])
    assert levels > n  # contact is drawn in (most) frames: the pressure data is really there
    size_mb = page.stat().st_size / 1e6
    assert size_mb < 30, f"{size_mb:.1f} MB"


# -- wrapped paths: the knee quadriceps over the condyle cylinder --------------------------------
@pytest.fixture(scope="module")
def knee_result(tmp_path_factory):
    """A 6-frame run of examples/knee/knee_springs.yaml (flexion 0 → 90°: the quadriceps
    lifts off near extension and wraps the condyle cylinder in flexion)."""
    d = tmp_path_factory.mktemp("view-knee")
    text = (ROOT / "examples" / "knee" / "knee_springs.yaml").read_text()
    assert "frames: 51" in text
    (d / "knee.yaml").write_text(text.replace("frames: 51", "frames: 6"))
    assert main(["run", str(d / "knee.yaml"), "--out", str(d / "run"), "--no-progress", "--no-plots"]) == 0
    return d / "run"


def test_wrapped_quadriceps_polyline_has_the_model_length_and_lies_on_the_cylinder(knee_result):
    """The stored world polyline of the wrapped quadriceps at each frame: its length equals
    the path length the model wrote (forces.csv quadriceps.length_m, from the wrapping
    kernel) to 1e-3 relative (the chords of 15 arc segments); in flexion its arc points lie
    on the condyle cylinder (distance to the axis = 25 mm to float32 precision) and the
    path ends at the origin and insertion points."""
    import csv

    from openfdk.viewer.wrapview import ARC_POINTS

    data, _ = view_data(knee_result)
    scene, frames = data["scene"], data["frames"]
    (quad,) = [p for p in scene["paths"] if p["name"] == "quadriceps"]
    assert quad["kind"] == "muscle" and quad["wrap"] == {"offset": 0, "count": 2 + ARC_POINTS}
    W = unpack(frames["wrap_points"]).astype(float)
    poses = unpack(frames["poses"]).astype(float)
    rows = list(csv.DictReader(open(knee_result / "forces.csv")))
    names = [b["name"] for b in scene["bodies"]]
    thigh, shank = names.index("thigh"), names.index("shank")
    assert W.shape == (6, 2 + ARC_POINTS, 3)
    wrapped_frames = 0
    for f in range(6):
        pts = W[f]
        length = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
        assert length == pytest.approx(float(rows[f]["quadriceps.length_m"]), rel=1e-3)
        R_t, R_s = rotation_matrix(poses[f, thigh, 3:]), rotation_matrix(poses[f, shank, 3:])
        np.testing.assert_allclose(pts[0], poses[f, thigh, :3] + R_t @ [0.03, 0.0, 0.0], atol=1e-6)
        np.testing.assert_allclose(pts[-1], poses[f, shank, :3] + R_s @ [0.04, 0.15, 0.0], atol=1e-6)
        arc = pts[1:-1]
        if np.ptp(arc, axis=0).max() < 1e-9:  # lift-off: the arc collapses onto the origin point
            continue
        wrapped_frames += 1
        axis_W, c_W = R_t[:, 2], poses[f, thigh, :3] + R_t @ [0.0, -0.2, 0.0]  # the knee frame's z axis
        rel = arc - c_W
        r = np.linalg.norm(rel - np.outer(rel @ axis_W, axis_W), axis=1)
        np.testing.assert_allclose(r, 0.025, atol=1e-6)
    assert wrapped_frames >= 4  # wraps in flexion (the test is not vacuous)
    # the condyle cylinder itself is drawn on the thigh: on the knee frame, radius 25 mm
    (cyl,) = scene["wrap_surfaces"]
    assert cyl["kind"] == "cylinder" and cyl["body"] == thigh
    np.testing.assert_allclose(cyl["p_BS"], [0.0, -0.2, 0.0], atol=1e-12)
    np.testing.assert_allclose(cyl["dims"], [0.025] * 3, atol=1e-12)
    assert cyl["length"] == pytest.approx(0.1)


@needs_browser
def test_browser_draws_the_wrapped_knee_muscle(knee_result, tmp_path):
    page = write_view(knee_result, tmp_path / "knee.html")
    _img, log, requests = browse(f"{page.as_uri()}#frame=5&view=left", tmp_path, "knee")
    info = ready_info(log)
    assert "openfdk-view: error" not in log and "Uncaught" not in log, _console(log)
    assert requests == []
    assert (info["paths"], info["wrapped"]) == (1, 1)


@pytest.mark.parametrize("kind, dims", [("sphere", (0.02, 0.02, 0.02)), ("ellipsoid", (0.03, 0.02, 0.015))])
def test_sphere_and_ellipsoid_arcs_lie_on_the_surface_with_the_kernel_length(kind, dims):
    """A path from P to Q wrapping a sphere/ellipsoid (on a body rotated and moved): the
    polyline's points lie on the surface (x_Sᵀ diag(1/a², 1/b², 1/c²) x_S = 1) and its
    length is the wrapping kernel's path length to the chord error (1e-3 relative)."""
    from openfdk.forces.wrapping import WrappedPath, WrapSurface
    from openfdk.model.state import BodyStates
    from openfdk.viewer.wrapview import ARC_POINTS, polyline

    R_BS = rotation_matrix(quat_from_rotvec([0.2, -0.1, 0.3]))
    surf = WrapSurface("s", kind, 0, np.array([0.01, 0.0, 0.0]), R_BS, np.array(dims), np.zeros(3))
    path = WrappedPath([(0, np.array([0.01, 0.0, -0.08])), surf, (0, np.array([0.025, 0.004, 0.07]))], "p")
    state = BodyStates([[0.1, 0.2, 0.3]], [quat_from_rotvec([0.5, 0.4, -0.2])], [0])
    pts = polyline(path, state)
    assert pts.shape == (2 + ARC_POINTS, 3)
    l_kernel = float(path.evaluate(state, order=0)[0][0])
    length = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    straight = np.linalg.norm(pts[-1] - pts[0])
    assert length == pytest.approx(l_kernel, rel=1e-3) and l_kernel > straight * 1.01  # it wraps
    R_WS = state.R_WB[0] @ R_BS
    x_S = (pts[1:-1] - (state.p_WB[0] + state.R_WB[0] @ surf.p_BS)) @ R_WS
    np.testing.assert_allclose(np.sum(x_S ** 2 / np.array(dims) ** 2, axis=1), 1.0, atol=1e-6)
    T1, T2 = path.tangent_points(state)[1]  # the arc runs from the kernel's T1 to its T2
    np.testing.assert_allclose(pts[1], T1, atol=1e-9)
    np.testing.assert_allclose(pts[-2], T2, atol=1e-6)


def test_ellipsoid_paths_drawn_for_all_frames_are_each_frames_own_polyline():
    """wrapped_polylines draws the paths over ellipsoids frame by frame from one kernel call
    and one BodyStates per frame for all of them: each frame's rows are the polyline of
    that path alone at that frame's poses (its own kernel call), to the wrap solves'
    tolerance; a straight path beside them is drawn too, and a frame without poses is NaN."""
    from types import SimpleNamespace

    from openfdk.forces.wrapping import WrappedPath, WrapSurface
    from openfdk.model.state import BodyStates
    from openfdk.viewer.wrapview import n_points, polyline, wrapped_polylines

    R_BS = rotation_matrix(quat_from_rotvec([0.2, -0.1, 0.3]))
    surf = WrapSurface("s", "ellipsoid", 0, np.array([0.01, 0.0, 0.0]), R_BS, np.array([0.03, 0.02, 0.015]),
                       np.zeros(3))
    paths = [WrappedPath([(0, np.array([0.01, 0.0, -0.08])), surf, (0, np.array([0.025, 0.004, 0.07]))], "a"),
             WrappedPath([(0, np.array([0.012, 0.003, -0.075])), surf, (0, np.array([0.02, -0.004, 0.072]))], "b")]
    model = SimpleNamespace(bodies=[SimpleNamespace(column=0)])
    nf = 5
    poses = np.zeros((nf, 1, 7))
    for f in range(nf):
        poses[f, 0, :3] = [0.1 + 0.002 * f, 0.2, 0.3]
        poses[f, 0, 3:] = quat_from_rotvec([0.5 + 0.05 * f, 0.4, -0.2])
    poses[3] = np.nan
    out = wrapped_polylines(model, paths, poses)
    assert out.shape == (nf, sum(n_points(p) for p in paths), 3)
    rows = np.cumsum([0] + [n_points(p) for p in paths])
    for f in range(nf):
        if f == 3:
            assert np.isnan(out[f]).all()
            continue
        state = BodyStates(poses[f, :, :3], poses[f, :, 3:], [0])
        for k, path in enumerate(paths):
            own = polyline(path, state)
            assert np.linalg.norm(np.diff(own, axis=0), axis=1).sum() > 1.01 * np.linalg.norm(own[-1] - own[0])  # wraps
            np.testing.assert_allclose(out[f, rows[k]:rows[k + 1]], own, atol=1e-9)


def test_pop_reaction_arrows_push_the_condyles_along_the_plane_normals(tmp_path):
    """A POP run (point_on_plane TMJs with one-sided 20 kN reactions): each reaction arrow
    is the recorded reaction force along −n_W, the skull's plane normal in the world at that
    frame, applied at the condyle point; so POP and FDK runs compare by eye."""
    import csv

    from models import write_jaw_files
    from openfdk.fixtures.synthetic_jaw import plane_normal

    write_jaw_files(tmp_path, 12)
    out = tmp_path / "pop"
    assert main(["run", str(tmp_path / "pop.yaml"), str(tmp_path / "trial.c3d"), "--out", str(out), "--no-progress",
                 "--no-plots"]) == 0
    data, _ = view_data(out)
    frames, scene = data["frames"], data["scene"]
    reactions = {r["name"]: r for r in frames["reactions"]}
    assert set(reactions) == {"tmj_r_contact", "tmj_l_contact"}
    rows = list(csv.DictReader(open(out / "forces.csv")))
    poses = unpack(frames["poses"]).astype(float)
    skull = [b["name"] for b in scene["bodies"]].index("skull")
    loaded = 0
    for name, side in (("tmj_r_contact", -1), ("tmj_l_contact", 1)):
        F = unpack(reactions[name]["force"]).astype(float)
        for k, row in enumerate(rows):
            f = float(row[f"{name}.reaction"])
            n_W = rotation_matrix(poses[k, skull, 3:]) @ plane_normal(side)
            np.testing.assert_allclose(F[k], -f * n_W, atol=1e-3 * max(f, 1.0))
            loaded += f > 1.0
    assert loaded > 0  # the condyles are loaded at some frames: the test is not vacuous
    assert frames["arrow_scale"]["reaction"]["fmax"] > 1.0
