"""Tests of openfdk.io.force_plates (and openfdk.io.c3d_analog): force plates from C3D.

The files are written with ezc3d's writer.  Their channels are computed here by hand from
a KNOWN load in the plate frame — a point force F (action on the plate) applied at a known
point p of the surface plus a known free moment Tz — for each plate type:

* 2: Fx Fy Fz and M_O = (p − O) × F + (0, 0, Tz) about the sensor origin O, where
  p − O = p + ORIGIN (ORIGIN is the vector from O to the surface centre C, c3d.org);
* 1: Fx Fy Fz, p_x, p_y, Tz;
* 3: the eight Kistler channels, sensors at (±a, ±b) in the corner quadrants, O at depth
  az0 under C, the load split between the sensors so that the Kistler formulae give F and
  M_O back;
* 4: type 2 through the inverse of a non-identity calibration matrix.

The plate's pose (rotation and surface centre) is chosen first and the corners derived
from it, so the expected lab-frame values do not reuse the reader's geometry.  Every
number stored in the file (channels, corners, ORIGIN, CAL_MATRIX) is exactly
representable in float32 (integers in mm, N and N·mm, dyadic fractions; poses built from
the Pythagorean triples 3-4-5 and 5-12-13), so the recovery is exact to round-off
(≤ 1e-9 m, ≤ 1e-9 relative).  ANALOG:OFFSET is patched into the file after writing
(ezc3d's Python writer always writes zeros).
"""

from __future__ import annotations

import inspect
import struct
from pathlib import Path

import ezc3d
import numpy as np
import pytest

from openfdk.io.c3d import C3DError, read_c3d
from openfdk.io.c3d_analog import read_analog
from openfdk.io.force_plates import DEFAULT_CUTOFF_HZ, read_force_plates

HALF_X, HALF_Y = 390.0, 325.0             # plate half sizes, mm (multiples of 65)
KISTLER_A, KISTLER_B = 128.0, 256.0        # sensor offsets, mm
FLOOR = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])   # plate x, y, z in the lab
RZ_90 = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
RZ_345 = np.array([[4.0, -3, 0], [3, 4, 0], [0, 0, 5]]) / 5      # yaw, cos 4/5
RX_51213 = np.array([[13.0, 0, 0], [0, 12, -5], [0, 5, 12]]) / 13  # tilt 22.6°
POSES = {
    "floor": (FLOOR, np.array([250.0, 300.0, 0.0])),
    "yaw90": (RZ_90 @ FLOOR, np.array([-400.0, 900.0, 5.0])),
    "tilted": (RZ_345 @ RX_51213 @ FLOOR, np.array([1000.0, -200.0, 150.0])),
}
ORIGIN_2 = np.array([2.0, -3.0, -41.0])    # mm, O → C (z negative: O below the surface)
ORIGIN_3 = np.array([KISTLER_A, KISTLER_B, -48.0])
# type-4 calibration matrix: diagonal gains times unit upper-triangular crosstalk (dyadic)
CAL = np.diag([2.0, 2.0, 4.0, 0.5, 0.5, 1.0]) @ (np.eye(6) + np.array([
    [0, 0.25, 0, 0, 0, 0.125], [0, 0, -0.25, 0, 0, 0], [0, 0, 0, 0.125, 0, 0],
    [0, 0, 0, 0, 0.25, 0], [0, 0, 0, 0, 0, -0.25], [0, 0, 0, 0, 0, 0]]))
N_CHANNELS = {1: 6, 2: 6, 3: 8, 4: 6}
UNITS = {1: ["N"] * 3 + ["mm"] * 2 + ["Nmm"], 2: ["N"] * 3 + ["Nmm"] * 3, 3: ["N"] * 8,
         4: ["V"] * 6}


# ---------------------------------------------------------------------------------------
# Known loads and the channels they produce
# ---------------------------------------------------------------------------------------

def known_load(n, start, stop, peak=800.0):
    """Action F (n, 3) N and point of application p (n, 3) mm about the surface centre,
    free moment tz (n,) N·mm, all plate frame and integers; zero outside [start, stop)."""
    u = np.clip((np.arange(n) - start) / (stop - start), 0.0, 1.0)
    on = (np.arange(n) >= start) & (np.arange(n) < stop)
    fz = np.round(peak * np.sin(np.pi * u)) * on
    force = np.column_stack((np.round(0.15 * fz * np.cos(3 * u)), np.round(-0.1 * fz), fz))
    p = np.column_stack((np.round(-150 + 300 * u), np.round(60 * np.sin(2 * np.pi * u)),
                         np.zeros(n))) * on[:, None]
    tz = np.round(4000 * np.sin(2 * np.pi * u)) * on
    return force, p, tz


def moment_about_origin(force, p, tz, r):
    """M_O = (p − O) × F + Tz ẑ, with p − O = p + r (r: C − O)."""
    m = np.cross(p + r, force)
    m[:, 2] += tz
    return m


def inverse_unit_upper(matrix):
    """Exact inverse of D (I + U), U strictly upper triangular: (I − U + U² − …) D⁻¹."""
    d = np.diag(np.diag(matrix))
    u = np.linalg.inv(d) @ matrix - np.eye(len(matrix))      # exact: D is a power of 2
    inverse, term = np.eye(len(matrix)), np.eye(len(matrix))
    for _ in range(len(matrix)):
        term = -term @ u
        inverse = inverse + term
    return inverse @ np.diag(1.0 / np.diag(matrix))


def channels_for(kind, force, p, tz):
    """The channel values (n, k) of plate ``kind`` under the known load (N, N·mm, mm)."""
    if kind == 1:
        return np.column_stack((force, p[:, :2], tz))
    if kind == 3:
        a, b, az0 = ORIGIN_3
        m = moment_about_origin(force, p, tz, np.array([0.0, 0.0, az0]))
        s, x, y, d, e = force[:, 2], m[:, 0] / b, m[:, 1] / a, m[:, 2] / (2 * b), m[:, 2] / (2 * a)
        return np.column_stack(((force[:, 0] - d) / 2, (force[:, 0] + d) / 2,
                                (force[:, 1] + e) / 2, (force[:, 1] - e) / 2,
                                (s + x - y) / 4, (s + x + y) / 4, (s - x + y) / 4, (s - x - y) / 4))
    w = np.column_stack((force, moment_about_origin(force, p, tz, ORIGIN_2)))
    return w if kind == 2 else w @ inverse_unit_upper(CAL).T


def corners_of(rotation, centre):
    local = np.array([[HALF_X, HALF_Y, 0], [-HALF_X, HALF_Y, 0],
                      [-HALF_X, -HALF_Y, 0], [HALF_X, -HALF_Y, 0]])
    return centre + local @ rotation.T


# ---------------------------------------------------------------------------------------
# Writing the file (ezc3d) and patching ANALOG:OFFSET
# ---------------------------------------------------------------------------------------

def parameter_data(raw, group, name):
    """(kind, dims, offset of the data) of parameter ``group:name`` in an Intel C3D file's
    bytes ``raw``, parsed here (not by the reader under test)."""
    pos, groups = (raw[0] - 1) * 512 + 4, {}
    while True:
        n_name, item_id = struct.unpack_from("bb", raw, pos)
        label = raw[pos + 2:pos + 2 + abs(n_name)].decode().upper()
        at = pos + 2 + abs(n_name)
        (step,) = struct.unpack_from("<H", raw, at)
        if item_id < 0:
            groups[-item_id] = label
        elif groups.get(item_id) == group and label == name:
            kind, n_dims = struct.unpack_from("bB", raw, at + 2)
            return kind, list(raw[at + 4:at + 4 + n_dims]), at + 4 + n_dims
        assert n_name and step, f"{group}:{name} not found"
        pos = at + step


def patch_analog_offset(path, offsets):
    """Overwrite the int16 values of ANALOG:OFFSET in an Intel C3D file."""
    raw = bytearray(Path(path).read_bytes())
    kind, dims, at = parameter_data(raw, "ANALOG", "OFFSET")
    assert kind == 2 and dims == [len(offsets)]
    struct.pack_into(f"<{len(offsets)}h", raw, at, *[int(o) for o in offsets])
    Path(path).write_bytes(bytes(raw))


def write_plates(path, plates, values, *, point_rate=100.0, ratio=10, scale=None,
                 offset=None, gen_scale=1.0, units=None, zero=(0, 0), point_units="mm",
                 exact=True, points=None, labels=None):
    """A C3D file whose analog channels hold ``values (n_samples, n_channels)`` after
    scaling ((stored − offset) × scale × gen_scale); ``plates``: dicts with ``type``,
    ``corners (4, 3)``, ``origin (3,)``, ``channel`` (1-based), optional ``cal (6, 6)``."""
    values = np.asarray(values, dtype=float)
    n_samples, n_channels = values.shape
    n_frames = n_samples // ratio
    scale = np.ones(n_channels) if scale is None else np.asarray(scale, dtype=float)
    offset = np.zeros(n_channels) if offset is None else np.asarray(offset, dtype=float)
    stored = values / (scale * gen_scale) + offset
    finite = np.isfinite(stored)
    if exact:
        assert np.array_equal(stored[finite].astype(np.float32), stored[finite]), "float32"
        assert np.array_equal(((stored - offset) * (scale * gen_scale))[finite], values[finite])

    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"] = [point_rate]
    point["LABELS"]["value"] = ["M1"] if labels is None else list(labels)
    point["UNITS"]["value"] = [point_units]
    if points is None:
        c3d["data"]["points"] = np.ones((4, 1, n_frames))
    else:  # (n_markers, n_frames, 3) in point units
        pts = np.ones((4, points.shape[0], n_frames))
        pts[:3] = np.transpose(points, (2, 0, 1))
        c3d["data"]["points"] = pts
    analog = c3d["parameters"]["ANALOG"]
    analog["RATE"]["value"] = [point_rate * ratio]
    analog["LABELS"]["value"] = [f"A{i + 1}" for i in range(n_channels)]
    analog["SCALE"]["value"] = scale
    analog["GEN_SCALE"]["value"] = [gen_scale]
    analog["UNITS"]["value"] = list(units) if units is not None else ["V"] * n_channels
    # ezc3d (1.7) writes value / (SCALE × GEN_SCALE) and reads (stored − |OFFSET|) × SCALE
    # × GEN_SCALE: checked below, before OFFSET is patched in
    c3d["data"]["analogs"] = (stored * scale * gen_scale).T[None]
    width = max(len(pl["channel"]) for pl in plates) if plates else 6
    channel = np.zeros((width, max(len(plates), 1)), dtype=int)
    for k, pl in enumerate(plates):
        channel[:len(pl["channel"]), k] = pl["channel"]
    fp = c3d["parameters"]["FORCE_PLATFORM"]
    fp["USED"]["value"] = [len(plates)]
    fp["TYPE"]["value"] = [pl["type"] for pl in plates]
    fp["ZERO"]["value"] = list(zero)
    fp["CHANNEL"]["value"] = channel
    if plates and all("corners" in pl for pl in plates):
        fp["CORNERS"]["value"] = np.stack([pl["corners"].T for pl in plates], axis=2)
    if plates and all("origin" in pl for pl in plates):
        fp["ORIGIN"]["value"] = np.column_stack([pl["origin"] for pl in plates])
    if any("cal" in pl for pl in plates):
        fp["CAL_MATRIX"]["value"] = np.stack([pl.get("cal", np.eye(6)) for pl in plates], axis=2)
    c3d.write(str(path))
    written = ezc3d.c3d(str(path))["data"]["analogs"][0].T
    np.testing.assert_allclose(written, stored * scale * gen_scale, rtol=0 if exact else 1e-7)
    if np.any(offset):
        patch_analog_offset(path, offset)
    return path


def plate_file(tmp_path, kind, pose="floor", n_frames=60, ratio=10, *, name=None,
               load=None, edit=None, origin=None, units=None, plate=None, **options):
    """File with one plate of ``kind`` at ``pose`` under the known load (or ``load`` =
    (force, p, tz)); ``edit(values)`` changes the channel values, ``origin`` the ORIGIN
    stored, ``plate`` other FORCE_PLATFORM entries; ``options`` go to :func:`write_plates`.
    Returns (path, force, p, tz): the load in the plate frame at the analog rate."""
    n = n_frames * ratio
    force, p, tz = load or known_load(n, 15 * ratio, (n_frames - 8) * ratio)
    values = channels_for(kind, force, p, tz)
    values = values if edit is None else edit(values)
    rotation, centre = POSES[pose]
    entry = {"type": kind, "corners": corners_of(rotation, centre),
             "origin": (ORIGIN_3 if kind == 3 else ORIGIN_2) if origin is None else origin,
             "channel": list(range(1, N_CHANNELS[kind] + 1)), **({"cal": CAL} if kind == 4 else {})}
    entry.update(plate or {})
    path = tmp_path / (name or f"type{kind}_{pose}.c3d")
    write_plates(path, [{k: v for k, v in entry.items() if v is not None}], values, ratio=ratio,
                 units=UNITS[kind] if units is None else units, **options)
    return path, force, p, tz


def expected(kind, pose, force, p, tz):
    """Lab-frame reaction on the subject, SI: force, moment about the reported origin,
    centre of pressure, free moment; and that origin.  ``pose``: a name of POSES or
    (rotation, centre mm)."""
    rotation, centre = POSES[pose] if isinstance(pose, str) else pose
    r = {1: np.zeros(3), 2: ORIGIN_2, 4: ORIGIN_2, 3: np.array([0, 0, ORIGIN_3[2]])}[kind]
    m_o = moment_about_origin(force, p, tz, r)
    return {"force": -force @ rotation.T, "moment": -m_o @ rotation.T * 1e-3,
            "cop": (centre + p @ rotation.T) * 1e-3,
            "free_moment": -(tz * 1e-3)[:, None] * rotation[:, 2],
            "origin": (centre - rotation @ r) * 1e-3}


def assert_matches(plate, want, rows=slice(None), threshold=20.0):
    loaded = want["force"][rows] @ plate.rotation[:, 2] < -threshold
    np.testing.assert_array_equal(plate.loaded, loaded)
    np.testing.assert_allclose(plate.force, want["force"][rows], rtol=0, atol=1e-9 * 800)
    np.testing.assert_allclose(plate.moment, want["moment"][rows], rtol=0, atol=1e-9 * 300)
    np.testing.assert_allclose(plate.cop[loaded], want["cop"][rows][loaded], rtol=0, atol=1e-9)
    np.testing.assert_allclose(plate.free_moment[loaded], want["free_moment"][rows][loaded],
                               rtol=0, atol=1e-9 * 4.0)
    np.testing.assert_allclose(plate.origin, want["origin"], rtol=0, atol=1e-12)
    assert np.isnan(plate.cop[~loaded]).all() and np.isnan(plate.free_moment[~loaded]).all()


# ---------------------------------------------------------------------------------------
# Exact recovery, every type, every pose
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("pose", sorted(POSES))
@pytest.mark.parametrize("kind", [1, 2, 3, 4])
def test_known_load_is_recovered_exactly(tmp_path, kind, pose):
    path, force, p, tz = plate_file(tmp_path, kind, pose, scale=np.full(N_CHANNELS[kind], 0.25),
                                    offset=np.arange(3, 3 + N_CHANNELS[kind]), gen_scale=2.0)
    (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    want = expected(kind, pose, force, p, tz)
    assert plate.name == "FP1" and plate.type == kind and plate.rate == 1000.0
    assert plate.loaded.sum() > 300 and not plate.invalid.any()
    assert_matches(plate, want)
    np.testing.assert_allclose(plate.corners, corners_of(*POSES[pose]) * 1e-3, atol=1e-15)
    np.testing.assert_allclose(plate.rotation, POSES[pose][0], atol=1e-15)
    (decimated,) = read_force_plates(path, cutoff_hz=0)          # every 10th sample
    assert decimated.rate == 100.0
    assert_matches(decimated, want, rows=slice(None, None, 10))


def test_four_plates_in_one_file_with_shuffled_channels(tmp_path):
    """One plate of each type in one file, the analog channels in reverse order."""
    n, values, plates, wants, units = 400, [], [], [], []
    for k, (kind, pose) in enumerate([(2, "floor"), (3, "yaw90"), (4, "tilted"), (1, "yaw90")]):
        force, p, tz = known_load(n, 50 + 20 * k, 350 - 10 * k, peak=600.0 + 50 * k)
        values.append(channels_for(kind, force, p, tz))
        units += UNITS[kind]
        rotation, centre = POSES[pose]
        placed = (rotation, centre + [0.0, 1000.0 * k, 0.0])
        plates.append({"type": kind, "corners": corners_of(*placed),
                       "origin": ORIGIN_3 if kind == 3 else ORIGIN_2,
                       **({"cal": CAL} if kind == 4 else {})})
        wants.append(expected(kind, placed, force, p, tz))
    values = np.column_stack(values)
    n_channels, start = values.shape[1], 0
    for pl in plates:                      # original column c is stored as channel n − c
        pl["channel"] = [n_channels - start - j for j in range(N_CHANNELS[pl["type"]])]
        start += N_CHANNELS[pl["type"]]
    path = write_plates(tmp_path / "four.c3d", plates, values[:, ::-1], units=units[::-1])
    result = read_force_plates(path, cutoff_hz=0, rate="analog")
    assert [(pl.name, pl.type) for pl in result] == [("FP1", 2), ("FP2", 3), ("FP3", 4), ("FP4", 1)]
    for plate, want in zip(result, wants):
        assert_matches(plate, want)


# ---------------------------------------------------------------------------------------
# ezc3d's own extraction: the same numbers where it is right, and where it is not
# ---------------------------------------------------------------------------------------

def ezc3d_platform(path):
    return ezc3d.c3d(str(path), extract_forceplat_data=True)["data"]["platform"][0]


@pytest.mark.parametrize("pose", ["floor", "tilted"])
@pytest.mark.parametrize("kind", [1, 2, 3, 4])
def test_matches_ezc3d_extraction(tmp_path, kind, pose):
    """ezc3d gives the action on the plate in the file's units (N, N·mm, mm) and the
    moment about the surface centre; openfdk the reaction, SI, about the sensor origin."""
    path, *_ = plate_file(tmp_path, kind, pose)
    (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    theirs, on = ezc3d_platform(path), plate.loaded
    np.testing.assert_allclose(plate.force, -theirs["force"].T, rtol=0, atol=1e-9)
    np.testing.assert_allclose(plate.cop[on], theirs["center_of_pressure"].T[on] * 1e-3,
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(plate.free_moment[on], -theirs["Tz"].T[on] * 1e-3, rtol=0, atol=1e-12)
    centre = plate.corners.mean(axis=0)
    moment_c = plate.moment + np.cross(plate.origin - centre, plate.force)   # about C
    sign = 1.0 if kind == 1 else -1.0        # ezc3d's type-1 moment has the other sign
    np.testing.assert_allclose(moment_c, sign * theirs["moment"].T * 1e-3, rtol=0, atol=1e-12)


def test_ezc3d_ignores_analog_units(tmp_path):
    """Moments stored in N·m with POINT:UNITS mm: openfdk converts them; ezc3d mixes N·m
    and N·mm and its centre of pressure is off by metres."""
    path, force, p, tz = plate_file(tmp_path, 2, units=["N"] * 3 + ["Nm"] * 3, exact=False,
                                    edit=lambda v: np.column_stack((v[:, :3], v[:, 3:] * 1e-3)))
    (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    want, on = expected(2, "floor", force, p, tz), plate.loaded
    np.testing.assert_allclose(plate.cop[on], want["cop"][on], rtol=0, atol=1e-6)
    np.testing.assert_allclose(plate.free_moment[on], want["free_moment"][on], rtol=0, atol=1e-6)
    error = np.abs(ezc3d_platform(path)["center_of_pressure"].T[on] * 1e-3 - want["cop"][on])
    assert error.max() > 0.1


def test_signed_analog_offset(tmp_path):
    """value = (stored − OFFSET) × SCALE × GEN_SCALE with a negative OFFSET: openfdk is
    exact; ezc3d subtracts |OFFSET| (its analogs differ by 2 |OFFSET| × scales)."""
    offset = np.array([-7, 3, -2, 5, -11, 1])
    path, force, p, tz = plate_file(tmp_path, 2, scale=np.full(6, 0.5), offset=offset,
                                    gen_scale=4.0)
    (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    assert_matches(plate, expected(2, "floor", force, p, tz))
    theirs = ezc3d.c3d(str(path))["data"]["analogs"][0].T
    ours = read_analog(path).values
    np.testing.assert_allclose(theirs - ours, np.tile((offset - np.abs(offset)) * 2.0,
                                                      (len(ours), 1)))


def test_kistler_positive_az0(tmp_path):
    """az0 stored positive (the distance, without its sign): openfdk negates it with a
    note; ezc3d negates a and b too, which mirrors its centre of pressure."""
    path, force, p, tz = plate_file(tmp_path, 3, origin=ORIGIN_3 * [1, 1, -1])
    (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    assert_matches(plate, expected(3, "floor", force, p, tz))
    assert any("az0" in note for note in plate.notes)
    on = plate.loaded
    mirrored = ezc3d_platform(path)["center_of_pressure"].T[on] * 1e-3
    assert np.abs(mirrored - plate.cop[on]).max() > 0.1


def test_amti_positive_origin_z_is_the_reverse_vector(tmp_path):
    path, force, p, tz = plate_file(tmp_path, 2, origin=-ORIGIN_2)
    (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    assert_matches(plate, expected(2, "floor", force, p, tz))
    assert any("ORIGIN z > 0" in note for note in plate.notes)


# ---------------------------------------------------------------------------------------
# Threshold, baseline, filter, resampling
# ---------------------------------------------------------------------------------------

def test_threshold(tmp_path):
    path, force, p, tz = plate_file(tmp_path, 2)
    want = expected(2, "floor", force, p, tz)
    for threshold in (0.0, 20.0, 200.0):
        (plate,) = read_force_plates(path, threshold_n=threshold, cutoff_hz=0, rate="analog")
        assert plate.threshold_n == threshold
        np.testing.assert_array_equal(plate.loaded, force[:, 2] > threshold)
        assert_matches(plate, want, threshold=threshold)
    (default,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    np.testing.assert_array_equal(default.loaded, force[:, 2] > 20.0)
    with pytest.raises(ValueError, match="threshold_n"):
        read_force_plates(path, threshold_n=-1.0)


def test_zero_baseline(tmp_path):
    """A constant bias on every channel is removed by FORCE_PLATFORM:ZERO (frames 1–10,
    unloaded); with ZERO = 0, 0 or ezc3d's default 1, 0 it stays."""
    bias = lambda v: v + np.array([6.0, -3.0, 12.0, 500.0, -250.0, 125.0])  # noqa: E731
    for zero, removed in [((1, 10), True), ((0, 10), True), ((0, 0), False), ((1, 0), False)]:
        path, force, p, tz = plate_file(tmp_path, 2, edit=bias, zero=zero, name=f"z{zero}.c3d")
        (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
        want = expected(2, "floor", force, p, tz)
        if removed:
            assert_matches(plate, want)
        else:
            assert np.abs(plate.force - want["force"]).max() > 5


def test_filter_default_is_the_markers_and_constant_passes_unchanged(tmp_path):
    from openfdk.io.markers import MarkerTrajectories
    from openfdk.analysis.jobs import DEFAULT_CUTOFF_HZ as JOBS_DEFAULT

    marker_default = inspect.signature(MarkerTrajectories).parameters["cutoff_hz"].default
    assert DEFAULT_CUTOFF_HZ == JOBS_DEFAULT == marker_default == 6.0
    n = 600
    load = (np.tile([120.0, -80.0, 700.0], (n, 1)), np.tile([-40.0, 25.0, 0.0], (n, 1)),
            np.full(n, 1500.0))
    path, force, p, tz = plate_file(tmp_path, 3, "tilted", load=load)
    (plate,) = read_force_plates(path, rate="analog")               # 6 Hz
    assert plate.cutoff_hz == 6.0 and plate.loaded.all()
    assert_matches(plate, expected(3, "tilted", force, p, tz))
    (same,) = read_force_plates(path, cutoff_hz=6.0, rate="analog")
    np.testing.assert_array_equal(same.force, plate.force)


def test_filter_smooths_a_step_without_lag_and_keeps_the_cop(tmp_path):
    """A force step at a fixed point: the filtered force rises smoothly, symmetric about
    the step (zero lag); F and M are filtered before the centre of pressure is computed,
    so the centre of pressure stays exactly at the point while the force ramps up."""
    n, step = 600, 300
    fz = np.where(np.arange(n) >= step, 800.0, 0.0)
    force = np.column_stack((0.25 * fz, -0.125 * fz, fz))
    load = (force, np.tile([100.0, -50.0, 0.0], (n, 1)), 0.0 * fz)
    path, force, p, tz = plate_file(tmp_path, 2, load=load)
    (raw,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    (smooth,) = read_force_plates(path, cutoff_hz=10.0, rate="analog")
    up = smooth.force[:, 2]                                      # lab z: up
    assert np.max(np.abs(np.diff(raw.force[:, 2]))) == 800.0
    assert np.max(np.abs(np.diff(up))) < 30.0                      # 800 N spread over ≳ 30 ms
    assert abs(up[step - 1] + up[step] - 800.0) < 1.0              # antisymmetric about the step
    assert 0 < up[step - 10] < 400 < up[step + 10] < 800
    want = expected(2, "floor", force, p, tz)
    on = smooth.loaded
    assert on.sum() > 250 and not on[:step - 40].any()
    np.testing.assert_allclose(smooth.cop[on], want["cop"][on], rtol=0, atol=1e-9)


def test_resampling_to_the_point_rate(tmp_path):
    """rate='point': the first analog sample of every frame, at the markers' times; with
    the filter on it is the filtered analog signal decimated."""
    path, force, p, tz = plate_file(tmp_path, 4, "yaw90", n_frames=50, ratio=20)
    marker_time = read_c3d(path).time
    for cutoff in (0, 12.0):
        (dense,) = read_force_plates(path, cutoff_hz=cutoff, rate="analog")
        (frames,) = read_force_plates(path, cutoff_hz=cutoff)
        assert dense.rate == 2000.0 and frames.rate == 100.0 and len(frames.time) == 50
        np.testing.assert_allclose(frames.time, marker_time, rtol=0, atol=1e-12)
        np.testing.assert_allclose(dense.time[::20], marker_time, rtol=0, atol=1e-12)
        for field in ("force", "moment", "cop", "free_moment", "loaded"):
            np.testing.assert_array_equal(getattr(frames, field), getattr(dense, field)[::20])
    assert_matches(read_force_plates(path, cutoff_hz=0)[0], expected(4, "yaw90", force, p, tz),
                   rows=slice(None, None, 20))
    with pytest.raises(ValueError, match="below 50 Hz"):
        read_force_plates(path, cutoff_hz=60.0)                      # aliasing at 100 Hz
    read_force_plates(path, cutoff_hz=60.0, rate="analog")


def test_analog_rate_equal_to_point_rate(tmp_path):
    path, force, p, tz = plate_file(tmp_path, 1, "tilted", n_frames=300, ratio=1)
    (plate,) = read_force_plates(path, cutoff_hz=0)
    assert plate.rate == 100.0
    assert_matches(plate, expected(1, "tilted", force, p, tz))


# ---------------------------------------------------------------------------------------
# Bad input: one line naming the file and the parameter
# ---------------------------------------------------------------------------------------

def assert_refused(path, parameter, *words, **options):
    with pytest.raises(C3DError) as info:
        read_force_plates(path, **options)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{path}: ") and parameter in message, message
    for word in words:
        assert word in message, message
    return message


def test_missing_and_zero_area_corners(tmp_path):
    path, *_ = plate_file(tmp_path, 2, plate={"corners": None})
    assert assert_refused(path, "FORCE_PLATFORM:CORNERS") == \
        f"{path}: FORCE_PLATFORM:CORNERS: missing (1 plate declared)"
    for name, corners in [("point", np.zeros((4, 3))),
                          ("line", np.array([[0.0, 0, 0], [100, 0, 0], [200, 0, 0], [300, 0, 0]]))]:
        path, *_ = plate_file(tmp_path, 2, name=f"{name}.c3d", plate={"corners": corners})
        assert_refused(path, "FORCE_PLATFORM:CORNERS", "plate 1 has zero area")


def test_channel_beyond_the_analog_channels(tmp_path):
    path, *_ = plate_file(tmp_path, 2, plate={"channel": [1, 2, 3, 4, 5, 30]})
    assert_refused(path, "FORCE_PLATFORM:CHANNEL", "channel 30", "6 analog channels")
    path, *_ = plate_file(tmp_path, 3, name="short.c3d", plate={"channel": [1, 2, 3, 4, 5, 6]})
    assert_refused(path, "FORCE_PLATFORM:CHANNEL", "needs 8")


@pytest.mark.parametrize("kind, words", [(5, "type 5"), (6, "type 6"), (7, "type 7 (Kistler"),
                                         (11, "split-belt"), (21, "AMTI stairs"), (0, "type 0")])
def test_unsupported_type_is_refused_by_name(tmp_path, kind, words):
    path, *_ = plate_file(tmp_path, 2, plate={"type": kind})
    assert_refused(path, "FORCE_PLATFORM:TYPE", words, "plate 1", "types 1, 2, 3 and 4")


def test_other_missing_or_bad_parameters(tmp_path):
    path, *_ = plate_file(tmp_path, 4, plate={"cal": None})
    assert_refused(path, "FORCE_PLATFORM:CAL_MATRIX", "missing", "plate 1 is type 4")
    path, *_ = plate_file(tmp_path, 4, name="zero_cal.c3d", plate={"cal": np.zeros((6, 6))})
    assert_refused(path, "FORCE_PLATFORM:CAL_MATRIX", "all zeros")
    path, *_ = plate_file(tmp_path, 2, name="no_origin.c3d", plate={"origin": None})
    assert_refused(path, "FORCE_PLATFORM:ORIGIN", "missing")
    path, *_ = plate_file(tmp_path, 3, name="no_ab.c3d", origin=np.array([0.0, 256, -48]))
    assert_refused(path, "FORCE_PLATFORM:ORIGIN", "positive sensor offsets")
    path, *_ = plate_file(tmp_path, 2, name="volts.c3d", units=["N", "V", "N", "Nmm", "Nmm", "Nmm"])
    assert_refused(path, "ANALOG:UNITS", "channel 2", "'V'")
    plate_file(tmp_path, 1, name="no_origin_type1.c3d", plate={"origin": None})   # not needed


def test_nan_analog_data_is_flagged_not_raised(tmp_path):
    def holes(values):
        values = values.copy()
        values[300:305, 2] = np.nan                   # Fz, frame 30
        values[451, 4] = np.nan                       # My, frame 45
        return values

    path, force, p, tz = plate_file(tmp_path, 2, edit=holes)
    want = expected(2, "floor", force, p, tz)
    bad = np.zeros(len(force), bool)
    bad[300:305] = bad[451] = True
    (dense,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    np.testing.assert_array_equal(dense.invalid, bad)
    assert not dense.loaded[bad].any() and np.isnan(dense.cop[bad]).all()
    assert any("NaN analog data" in note for note in dense.notes)
    good = ~bad & dense.loaded
    np.testing.assert_allclose(dense.cop[good], want["cop"][good], rtol=0, atol=1e-9)
    (frames,) = read_force_plates(path)                              # filtered, 100 Hz
    assert np.flatnonzero(frames.invalid).tolist() == [30, 45]
    assert not frames.loaded[[30, 45]].any()
    assert frames.loaded.sum() > 35 and np.isfinite(frames.cop[frames.loaded]).all()


def test_never_loaded_plate_and_no_plates(tmp_path):
    n = 600
    path, *_ = plate_file(tmp_path, 3, load=(np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)))
    (plate,) = read_force_plates(path)
    assert plate.never_loaded and np.isnan(plate.cop).all() and not plate.invalid.any()
    assert any("never loaded" in note for note in plate.notes)
    empty = write_plates(tmp_path / "none.c3d", [], np.zeros((100, 2)), units=["N", "N"])
    assert read_force_plates(empty) == []


# ---------------------------------------------------------------------------------------
# Files as vendors write them: the channels' sign, unused plates, force-only files
# ---------------------------------------------------------------------------------------

def on_the_subject(kind):
    """Channel edit: the force on the subject instead of the action, as BTS and Qualisys
    files hold it (Fz < 0 under load along the downward plate z): every force and moment
    channel negated, type 1's centre-of-pressure channels kept."""
    sign = np.array([-1.0, -1, -1, 1, 1, -1]) if kind == 1 else -1.0
    return lambda values: values * sign


@pytest.mark.parametrize("pose", ["floor", "tilted"])
@pytest.mark.parametrize("kind", [1, 2, 3, 4])
def test_channels_holding_the_force_on_the_subject(tmp_path, kind, pose):
    """The same load written both ways gives the same reaction.  ezc3d takes the channels
    as they are: for a file holding the force on the subject its force, centre of
    pressure and free moment are openfdk's (for the action file, their negatives)."""
    path, force, p, tz = plate_file(tmp_path, kind, pose, edit=on_the_subject(kind))
    (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    assert_matches(plate, expected(kind, pose, force, p, tz))
    (note,) = [n for n in plate.notes if "force on the subject" in n]
    assert "to -800 N under load; 100.0 %" in note, note
    theirs, on = ezc3d_platform(path), plate.loaded
    np.testing.assert_allclose(plate.force, theirs["force"].T, rtol=0, atol=1e-9)
    np.testing.assert_allclose(plate.cop[on], theirs["center_of_pressure"].T[on] * 1e-3,
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(plate.free_moment[on], theirs["Tz"].T[on] * 1e-3, rtol=0, atol=1e-12)
    action, *_ = plate_file(tmp_path, kind, pose, name="action.c3d")
    (plate,) = read_force_plates(action, cutoff_hz=0, rate="analog")
    assert not any("force on the subject" in n for n in plate.notes)


@pytest.mark.parametrize("flip", [False, True])
def test_a_brief_pull_does_not_decide_the_sign(tmp_path, flip):
    """A plate ringing past zero after the foot leaves (40 N the other way for 10 ms) is
    not a load: the push decides, and those samples are not loaded."""
    def ring(values):
        values = on_the_subject(2)(values) if flip else values.copy()
        values[530:540, 2] = 40.0 if flip else -40.0
        return values

    path, force, p, tz = plate_file(tmp_path, 2, edit=ring)
    (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    assert any("force on the subject" in n for n in plate.notes) == flip
    want, rows = expected(2, "floor", force, p, tz), np.r_[0:530, 540:600]
    np.testing.assert_allclose(plate.force[rows], want["force"][rows], rtol=0, atol=1e-9)
    assert not plate.loaded[530:540].any() and plate.loaded.sum() == (force[:, 2] > 20).sum()


def two_plates(tmp_path, first_corners, first_load=False, name="two.c3d"):
    """Plate 1 with ``first_corners`` (mm) and no load (or the known load), plate 2 a
    floor plate under the known load; returns (path, expected of plate 2)."""
    n = 600
    force, p, tz = known_load(n, 150, 520)
    values = channels_for(2, force, p, tz)
    first = values.copy() if first_load else np.zeros_like(values)
    placed = (FLOOR, np.array([250.0, 1300.0, 0.0]))
    plates = [{"type": 2, "corners": first_corners, "origin": ORIGIN_2, "channel": list(range(1, 7))},
              {"type": 2, "corners": corners_of(*placed), "origin": ORIGIN_2, "channel": list(range(7, 13))}]
    path = write_plates(tmp_path / name, plates, np.column_stack((first, values)), units=UNITS[2] * 2)
    return path, expected(2, placed, force, p, tz)


@pytest.mark.parametrize("corners, words", [
    (np.zeros((4, 3)), "plate 1 has zero area"),
    (corners_of(FLOOR, np.array([2e5, 0.0, 0.0])), "plate 1 lies outside the lab (a corner coordinate of 200 m"),
])
def test_a_plate_whose_corners_are_no_plate(tmp_path, corners, words):
    """Some writers leave unused plates' parameters uninitialised (ezc3d's FP_Type1
    sample: corners of 1e10 m).  Never loaded, such a plate is left out with a warning and
    the others keep their names; loaded, it is refused."""
    from openfdk.io.ground_reactions import _plate_key

    path, want = two_plates(tmp_path, corners)
    with pytest.warns(UserWarning) as caught:
        (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    (message,) = [str(w.message) for w in caught]
    assert message.startswith(f"{path}: FORCE_PLATFORM:CORNERS: {words}"), message
    assert message.endswith("FP1 never carries more than 0 N, so it is left out")
    assert plate.name == "FP2" and _plate_key(plate) == {"FP2", "plate2", "2"}
    assert_matches(plate, want)
    loaded, _ = two_plates(tmp_path, corners, first_load=True, name="loaded.c3d")
    assert_refused(loaded, "FORCE_PLATFORM:CORNERS", words)


def force_only_file(tmp_path, corners_scale=1.0, name="force_only.c3d"):
    """A Kistler BioWare-like file: no 3D points, POINT:RATE and the header's rate 0,
    POINT:UNITS blank, ANALOG:UNITS padded with NUL (``N\\0``); one type-3 plate under the
    known load.  Returns (path, force, p, tz)."""
    n_frames = 60
    path, force, p, tz = plate_file(
        tmp_path, 3, n_frames=n_frames, name=name, points=np.zeros((0, n_frames, 3)), labels=[],
        point_units="", units=["N#"] * 8,
        plate={"corners": corners_of(*POSES["floor"]) * corners_scale})
    raw = bytearray(path.read_bytes())
    struct.pack_into("<f", raw, 20, 0.0)                       # header words 11–12: rate
    kind, dims, at = parameter_data(raw, "POINT", "RATE")
    assert kind == 4
    struct.pack_into("<f", raw, at, 0.0)
    kind, dims, at = parameter_data(raw, "ANALOG", "UNITS")
    assert kind == -1 and dims == [2, 8]
    raw[at:at + 16] = b"N\x00" * 8
    path.write_bytes(bytes(raw))
    return path, force, p, tz


def test_a_force_only_file(tmp_path):
    """No markers, no frame rate, no length unit: the frame is the header's analog samples
    per frame, the unit mm (the plate then measures 780 × 650 mm), each with a note."""
    path, force, p, tz = force_only_file(tmp_path)
    with pytest.raises(C3DError, match="contains no 3D points"):
        read_c3d(path)
    (plate,) = read_force_plates(path, cutoff_hz=0, rate="analog")
    assert plate.rate == 1000.0
    assert_matches(plate, expected(3, "floor", force, p, tz))
    assert "POINT:UNITS is blank: CORNERS and ORIGIN read in mm (a 780 × 650 mm plate)" in plate.notes
    (frames,) = read_force_plates(path, cutoff_hz=0)
    assert frames.rate == 100.0
    assert_matches(frames, expected(3, "floor", force, p, tz), rows=slice(None, None, 10))
    metres, *_ = force_only_file(tmp_path, corners_scale=1e-3, name="metres.c3d")
    assert_refused(metres, "POINT:UNITS", "blank", "0.78 × 0.65 mm", "give POINT:UNITS")


def test_mutated_files_read_or_refused(tmp_path):
    """Seeded random corruption of the parameter section: every file is read or refused
    with C3DError (pure Python: nothing can crash the process)."""
    path, *_ = plate_file(tmp_path, 4, n_frames=20)
    base = path.read_bytes()
    rng = np.random.default_rng(7)
    outcomes = {"read": 0, "refused": 0}
    section = range(512, 512 * (1 + base[512 + 2]))
    for _ in range(200):
        mutant = bytearray(base)
        for _ in range(rng.integers(1, 4)):
            mutant[rng.choice(section)] = rng.integers(256)
        target = tmp_path / "mutant.c3d"
        target.write_bytes(bytes(mutant))
        try:
            read_force_plates(target, cutoff_hz=0, rate="analog")
            outcomes["read"] += 1
        except C3DError as exc:
            assert "\n" not in str(exc)
            outcomes["refused"] += 1
    assert outcomes["read"] > 0 and outcomes["refused"] > 0


# ---------------------------------------------------------------------------------------
# The analog reader on other layouts, and the benchmark
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("processor, scale", [(84, -1.0), (84, 0.1), (85, -1.0), (86, -1.0),
                                              (86, 0.1)])
def test_analog_layout_of_independently_written_files(tmp_path, processor, scale):
    """tests/test_c3d.build_c3d (no ezc3d): Intel, DEC and MIPS, float and int16; its
    analog channels are zeros, its points ones: a misplaced read would show them."""
    from test_c3d import build_c3d

    path = tmp_path / "hand.c3d"
    path.write_bytes(build_c3d(["a", "b", "c"], np.ones((12, 3, 3)), 50.0, scale=scale,
                               processor=processor, analog_channels=4, analog_per_frame=8))
    analog = read_analog(path)
    assert analog.values.shape == (96, 4) and analog.samples_per_frame == 8
    assert analog.rate == 400.0 and analog.point_rate == 50.0 and not analog.values.any()
    assert read_force_plates(path) == []                                 # no FORCE_PLATFORM


def test_bench_record():
    from openfdk.bench import BENCHMARK_MODULES
    from openfdk.bench.force_plates import run

    assert "openfdk.bench.force_plates" in BENCHMARK_MODULES
    (record,) = run(quick=True)
    assert record["name"] == "force_plates_read_ms" and record["unit"] == "ms"
    assert 0 < record["value"] < 5000
