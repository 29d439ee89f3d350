"""Force plates of a C3D file: force, moment, centre of pressure and free moment, in the
lab frame and SI units (docs/force-plates.md).

Parameters read (C3D User Guide, "The FORCE_PLATFORM group"; c3d.org): ``USED``,
``TYPE``, ``CHANNEL`` (1-based analog channels, ``(channels per plate, plates)``),
``CORNERS`` (``(3, 4, plates)``, lab frame, POINT:UNITS), ``ORIGIN`` (``(3, plates)``),
``CAL_MATRIX`` (type 4, ``(6, 6, plates)``, column order), ``ZERO`` (optional); the
channels come from :func:`openfdk.io.c3d_analog.read_analog`.

Plate frame.  Corners are numbered by quadrant of the plate's x–y plane: 1 (+x, +y),
2 (−x, +y), 3 (−x, −y), 4 (+x, −y); x = mean of corner 2 → 1 and 3 → 4, y = mean of
4 → 1 and 3 → 2, z = x × y normalised (down, into a floor plate), y = z × x: any
orientation in the lab.  The surface centre C is the mean of the corners.

Action and reaction.  Every output is the reaction on the subject.  The channels' sign
convention is the vendor's: some write the action of the subject on the plate (Kistler's
BioWare: standing on a floor plate gives Fz > 0 along the plate's downward z), others the
force on the subject (BTS, Qualisys: Fz < 0 under load).  A subject pushes on a plate and
cannot pull it, so the sign is read from the data, per plate: the plate-normal force's
excursions beyond ``threshold_n`` on either side are summed, and the larger side is the
push (:func:`_push_sign`).  Channels that hold the force on the subject are read with
their sign reversed, with a note; a plate never loaded keeps the action convention.

ORIGIN.  For types 2 and 4 it is the vector from the plate's sensor origin O (where a
force gives no moment) to the surface centre C, in plate coordinates (c3d.org, TYPE-2:
"a vector pointing from the origin of the force plate coordinate system … to the …
geometric center of the … working surface"), so its z is negative for a plate mounted in
the floor.  A positive z (the older AMTI description, centre → origin) is read as the
reverse vector, all three components negated, as Visual3D and ezc3d do, with a note.
For type 3 (Kistler), ORIGIN = (a, b, az0): a, b the sensor offsets from the plate's
y and x axes (positive), az0 the depth of the sensor plane's origin O below the surface
(negative; a positive az0 is negated, with a note); O lies under C.  Type 1 does not use it.

Per type, action force F and moment M_O about O in plate coordinates (SI):

* 1: Fx Fy Fz, COPx COPy (relative to C), Tz: M_C = c × F + (0, 0, Tz).
* 2: Fx Fy Fz Mx My Mz, about O.
* 3: fx12 fx34 fy14 fy23 fz1 fz2 fz3 fz4 (Kistler, sensors at (±a, ±b) in the corner
  quadrants): F = (fx12 + fx34, fy14 + fy23, Σ fz), M_O = (b (fz1 + fz2 − fz3 − fz4),
  a (−fz1 + fz2 + fz3 − fz4), b (−fx12 + fx34) + a (fy14 − fy23)).
* 4: six channels in volts through CAL_MATRIX: [F; M_O] = CAL_MATRIX · V, the moment rows
  in N·(POINT:UNITS) (c3d.org, FORCE_PLATFORM:CAL_MATRIX).

Then M_C = M_O − r × F with r = ORIGIN (type 3: (0, 0, az0)); on the surface (z = 0 about
C) the centre of pressure is c = (−M_Cy / Fz, M_Cx / Fz, 0) and the free moment
Tz = M_Cz − (c_x Fy − c_y Fx) (the Kistler Force Plate Formulae, for any plate once M is
taken about the surface centre).

Units: ``ANALOG:UNITS`` N, kN (forces), N·mm, N·cm, N·m, kN·m (moments), mm, cm, m (type-1
centre of pressure) are converted to SI; a blank unit is the C3D default (N, N·POINT:UNITS,
POINT:UNITS); another unit is an error.  Type-4 channel units are not used (volts).

Processing order: baseline (``ZERO``) → SI → F and M_C at the analog rate → zero-lag
low-pass of F and M_C → resampling → centre of pressure and free moment → threshold.

* Baseline: when ``FORCE_PLATFORM:ZERO`` = (z1, z2) is not (0, 0), the mean of each plate
  channel over file frames max(z1, 1) … z2 (1 = the file's first frame) is subtracted
  (the plate must be unloaded there); an empty range (e.g. ezc3d's default (1, 0)) means none.
* Filter: order-2 Butterworth, zero lag (:mod:`openfdk.io.butterworth`), of F and M_C
  (linear in the channels; the centre of pressure, a ratio, is computed afterwards).
  ``cutoff_hz=None`` is the markers' default, 6 Hz (``MarkerTrajectories``,
  ``openfdk.analysis.jobs.DEFAULT_CUTOFF_HZ``): the same cut-off for markers and forces avoids
  the artefacts of inverse dynamics with mismatched filters (Kristianslund, Krosshaug &
  van den Bogert, J Biomech 45 (2012) 666–671).  ``cutoff_hz=0``: no filter.
* Resampling (``rate='point'``): decimation, one sample per video frame, the frame's
  first (taken at the marker sample's time), after the low-pass filter (which is then
  the anti-aliasing filter; the cut-off must lie below half the point rate).  Averaging
  the samples of a frame was not chosen: its mean belongs to the middle of the frame,
  a lag of (samples − 1) / (2 × analog rate) (4.5 ms at 1000/100 Hz) against the markers,
  and a box-car is a poor low-pass.  ``rate='analog'`` keeps every sample.
* Threshold: a frame is loaded when the plate-normal action Fz (the vertical push on a
  floor plate, after the sign above) exceeds ``threshold_n``; elsewhere the centre of
  pressure and free moment are NaN (force and moment are kept as measured).
* NaN analog data: the frames concerned are flagged (``invalid``, ``loaded`` False, a
  note); runs of finite samples are filtered separately (runs not longer than the
  filter's padding are left unfiltered).  Never an exception.
* A sample whose force exceeds ``MAX_FORCE_N`` or whose moment about the surface centre
  exceeds ``MAX_MOMENT_N_M`` (in SI, before the filter) is no measurement (plates
  saturate at ~40 kN and a few kN·m): C3DError naming the file, the plate and the time.

* A plate whose CORNERS are no plate (zero area, not finite, or beyond
  ``MAX_LAB_COORDINATE_M`` of the lab origin: some writers leave unused plates'
  parameters uninitialised) is left out with a warning when its channels never exceed
  ``threshold_n``, and refused otherwise.  The others keep their names (``FP1`` … by
  ``FORCE_PLATFORM`` order).

ezc3d's extraction (``extract_forceplat_data=True``) is not used: the centre of pressure
must come from the filtered F and M, and it is wrong in places (docs/force-plates.md);
tests/test_force_plates.py checks this module against it where it is right.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np

from openfdk.io.butterworth import butter_lowpass_sos, filtfilt_padlen, sosfiltfilt
from openfdk.io.c3d import MAX_LAB_COORDINATE_M, UNIT_TO_METRE, C3DError
from openfdk.io.c3d_analog import AnalogData, parameter_values, read_analog
from openfdk.io.markers import visible_segments

__all__ = ["DEFAULT_CUTOFF_HZ", "DEFAULT_THRESHOLD_N", "ForcePlateData", "read_force_plates"]

DEFAULT_CUTOFF_HZ = 6.0            # = openfdk.analysis.jobs.DEFAULT_CUTOFF_HZ (markers)
DEFAULT_THRESHOLD_N = 20.0
FILTER_ORDER = 2
#: the largest force (N) and moment (N·m) a plate sample may hold: beyond, no measurement
#: (the bounds of an ExternalLoads' data, :mod:`openfdk.forces.data_load_section`)
MAX_FORCE_N = 1e6
MAX_MOMENT_N_M = 1e6

CHANNEL_NAMES = {
    1: ("Fx", "Fy", "Fz", "COPx", "COPy", "Tz"),
    2: ("Fx", "Fy", "Fz", "Mx", "My", "Mz"),
    3: ("fx12", "fx34", "fy14", "fy23", "fz1", "fz2", "fz3", "fz4"),
    4: ("V1", "V2", "V3", "V4", "V5", "V6"),
}
#: what each channel of types 1–3 measures (AnalogData.si_factor)
CHANNEL_KINDS = {1: ("force",) * 3 + ("length",) * 2 + ("moment",),
                 2: ("force",) * 3 + ("moment",) * 3, 3: ("force",) * 8}
UNSUPPORTED_TYPES = {
    5: "type 5 (8 channels CZ DZ AZ BZ YAC XDC XAB YBD)",
    6: "type 6 (12 channels Fx Fy Fz per sensor, 12×12 CAL_MATRIX)",
    7: "type 7 (Kistler 8 channels with an 8×8 CAL_MATRIX)",
    11: "type 11 (Kistler split-belt treadmill)",
    12: "type 12 (Kistler split-belt treadmill)",
    21: "type 21 (AMTI stairs)",
}


@dataclass(frozen=True, eq=False)
class ForcePlateData:
    """One force plate of a trial, lab frame, SI units, all on the subject (reaction).

    Attributes:
        name: ``FP1``, ``FP2``, … in ``FORCE_PLATFORM`` order; ``type``: C3D plate type.
        time: ``(n,)`` s (at the point rate: the markers' sample times).
        force: ``(n, 3)`` N, the force on the subject.
        moment: ``(n, 3)`` N·m, the moment on the subject about ``origin``.
        cop: ``(n, 3)`` m, centre of pressure on the plate surface; NaN where not loaded.
        free_moment: ``(n, 3)`` N·m, the free moment on the subject, along the plate
            normal (its moment about the centre of pressure); NaN where not loaded.
        corners: ``(4, 3)`` m; ``origin``: ``(3,)`` m, the sensor origin O (type 1: the
            surface centre); ``rotation``: ``(3, 3)``, columns the plate x, y, z axes.
        loaded: ``(n,)`` bool, plate-normal force above ``threshold_n`` and valid data.
        invalid: ``(n,)`` bool, frames with NaN analog data on this plate's channels.
        rate: Hz of ``time``; ``cutoff_hz``: the low-pass used (None: unfiltered).
        notes: what was assumed or flagged (one sentence each).
    """

    name: str
    type: int
    time: np.ndarray
    force: np.ndarray
    moment: np.ndarray
    cop: np.ndarray
    free_moment: np.ndarray
    corners: np.ndarray
    origin: np.ndarray
    rotation: np.ndarray
    loaded: np.ndarray
    invalid: np.ndarray
    rate: float
    threshold_n: float
    cutoff_hz: float | None
    notes: tuple[str, ...] = ()

    @property
    def never_loaded(self) -> bool:
        return not bool(self.loaded.any())


@dataclass
class _Plate:
    index: int
    type: int
    channels: np.ndarray          # 0-based analog channel indices
    corners: np.ndarray           # (4, 3) m
    rotation: np.ndarray | None   # (3, 3) plate → lab; None: CORNERS are no plate (notes[0])
    r: np.ndarray                 # (3,) m, C − O in plate coordinates
    ab: tuple[float, float]       # type 3 sensor offsets, m
    cal: np.ndarray | None        # type 4 (6, 6)
    notes: list


def _values(analog: AnalogData, key: str, n_plates: int, per_plate: int, need: str,
            finite: bool = True):
    """Flat numbers of ``FORCE_PLATFORM:key``, at least ``per_plate × n_plates`` (all
    finite when ``finite``)."""
    value = parameter_values(analog.parameters, f"FORCE_PLATFORM:{key}")
    where = f"{analog.source}: FORCE_PLATFORM:{key}"
    if value is None or len(value) == 0:
        raise C3DError(f"{where}: missing ({n_plates} plate{'s' * (n_plates != 1)} "
                       f"declared{need})")
    if isinstance(value, list):
        raise C3DError(f"{where}: must hold numbers, found text {value!r}")
    if len(value) < per_plate * n_plates:
        raise C3DError(f"{where}: {len(value)} values for {n_plates} plates "
                       f"(needs {per_plate} per plate)")
    if finite and not np.all(np.isfinite(value[:per_plate * n_plates])):
        raise C3DError(f"{where}: holds values that are not finite")
    return value


def _plate_frame(corners: np.ndarray, where: str) -> np.ndarray:
    """Columns: the plate's x, y, z axes in the lab, from ``corners (4, 3)`` m (module
    docstring); C3DError naming ``where`` when the corners are no plate."""
    if not np.all(np.isfinite(corners)) or np.abs(corners).max() > MAX_LAB_COORDINATE_M:
        raise C3DError(f"{where} lies outside the lab (a corner coordinate of "
                       f"{np.nanmax(np.abs(corners)):.3g} m, beyond {MAX_LAB_COORDINATE_M:g} m)")
    x = 0.5 * ((corners[0] - corners[1]) + (corners[3] - corners[2]))
    y = 0.5 * ((corners[0] - corners[3]) + (corners[1] - corners[2]))
    z = np.cross(x, y)
    size = max(float(np.dot(x, x) + np.dot(y, y)), 1e-300)
    if not np.linalg.norm(z) > 1e-9 * size:
        raise C3DError(f"{where} has zero area (corners {np.round(corners * 1e3, 3).tolist()} mm)")
    z /= np.linalg.norm(z)
    x /= np.linalg.norm(x)
    return np.column_stack((x, np.cross(z, x), z))


def _plates(analog: AnalogData, n_plates: int, metres: float) -> list[_Plate]:
    """Every plate's parameters, checked (module docstring); C3DError otherwise."""
    src = analog.source
    types = _values(analog, "TYPE", n_plates, 1, "")[:n_plates].astype(int)
    for p, kind in enumerate(types):
        if kind not in CHANNEL_NAMES:
            what = UNSUPPORTED_TYPES.get(int(kind), f"type {kind}")
            raise C3DError(f"{src}: FORCE_PLATFORM:TYPE: plate {p + 1} is {what}, not "
                           f"supported (openfdk reads types 1, 2, 3 and 4)")
    corners = _values(analog, "CORNERS", n_plates, 12, "", finite=False)   # per plate below
    needs_origin = [p for p in range(n_plates) if types[p] != 1]
    origins = (_values(analog, "ORIGIN", n_plates, 3, f", plate {needs_origin[0] + 1} is "
                       f"type {types[needs_origin[0]]}") if needs_origin else None)
    channel = _values(analog, "CHANNEL", n_plates, 1, "")
    dims = analog.dims.get("FORCE_PLATFORM:CHANNEL", ())
    stride = dims[0] if len(dims) >= 2 else len(channel) // n_plates
    cal = None
    if 4 in types:
        first4 = int(np.flatnonzero(types == 4)[0]) + 1
        cal = _values(analog, "CAL_MATRIX", n_plates, 0, f", plate {first4} is type 4")
        cal_dims = analog.dims.get("FORCE_PLATFORM:CAL_MATRIX", ())
        rows, cols = (cal_dims[0], cal_dims[1]) if len(cal_dims) >= 2 else (6, 6)

    plates = []
    for p in range(n_plates):
        kind, notes = int(types[p]), []
        k = len(CHANNEL_NAMES[kind])
        if stride < k:
            raise C3DError(f"{src}: FORCE_PLATFORM:CHANNEL: {stride} channels per plate, "
                           f"plate {p + 1} (type {kind}) needs {k}")
        numbers = channel[p * stride:p * stride + k]
        bad = [c for c in numbers if not (np.isfinite(c) and c == int(c)
                                          and 1 <= c <= analog.n_channels)]
        if bad:
            raise C3DError(f"{src}: FORCE_PLATFORM:CHANNEL: plate {p + 1} uses analog channel "
                           f"{bad[0]:g}, the file has {analog.n_channels} analog channels")
        c = corners[12 * p:12 * p + 12].reshape(4, 3) * metres
        try:
            rotation = _plate_frame(c, f"{src}: FORCE_PLATFORM:CORNERS: plate {p + 1}")
        except C3DError as exc:        # read_force_plates: left out if never loaded
            rotation, notes = None, [str(exc)]
        r, ab, matrix = np.zeros(3), (0.0, 0.0), None
        if kind != 1:
            r = origins[3 * p:3 * p + 3] * metres
            if kind == 3:
                ab = (float(r[0]), float(r[1]))
                if not (ab[0] > 0 and ab[1] > 0):
                    raise C3DError(f"{src}: FORCE_PLATFORM:ORIGIN: plate {p + 1} (type 3) needs "
                                   f"positive sensor offsets a, b, got {r[0] / metres:g}, "
                                   f"{r[1] / metres:g}")
                r = np.array([0.0, 0.0, -abs(r[2])])
                if origins[3 * p + 2] > 0:
                    notes.append("ORIGIN az0 > 0 read as −az0 (the surface is above the "
                                 "sensor plane)")
            elif r[2] > 0:
                r = -r
                notes.append("ORIGIN z > 0 read as the vector from the surface centre to "
                             "the sensor origin, all components negated (as Visual3D)")
        if kind == 4:
            if rows < 6 or cols < 6:
                raise C3DError(f"{src}: FORCE_PLATFORM:CAL_MATRIX: dimensions {cal_dims}, "
                               f"type 4 needs 6 × 6 per plate")
            block = cal[p * rows * cols:(p + 1) * rows * cols]
            if len(block) < rows * cols or not np.all(np.isfinite(block)):
                raise C3DError(f"{src}: FORCE_PLATFORM:CAL_MATRIX: {len(cal)} values, no "
                               f"finite {rows} × {cols} matrix for plate {p + 1}")
            matrix = block.reshape(cols, rows).T[:6, :6].copy()    # column order
            if not np.any(matrix):
                raise C3DError(f"{src}: FORCE_PLATFORM:CAL_MATRIX: plate {p + 1} is all zeros")
        plates.append(_Plate(p, kind, numbers.astype(int) - 1, c, rotation, r, ab, matrix, notes))
    return plates


#: plate edge lengths (m) that make a blank POINT:UNITS millimetres
PLATE_EDGE_RANGE_M = (0.1, 3.0)


def _blank_units_as_mm(source: str, plates: list[_Plate]) -> None:
    """A blank POINT:UNITS (a file without 3D points: Kistler BioWare) is read as mm,
    the C3D custom, when every plate's edges then measure within PLATE_EDGE_RANGE_M;
    a note on each plate, C3DError otherwise."""
    lo, hi = PLATE_EDGE_RANGE_M
    for plate in plates:
        if plate.rotation is None:
            continue
        c = plate.corners
        edges = np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1)
        size = f"{edges[1] * 1e3:.3g} × {edges[0] * 1e3:.3g} mm"
        if not (edges.min() >= lo and edges.max() <= hi):
            raise C3DError(f"{source}: POINT:UNITS is blank, and FORCE_PLATFORM:CORNERS read "
                           f"in mm make plate {plate.index + 1} {size}: give POINT:UNITS")
        plate.notes.append(f"POINT:UNITS is blank: CORNERS and ORIGIN read in mm "
                           f"(a {size} plate)")


def _baseline(analog: AnalogData, x: np.ndarray, notes: list) -> np.ndarray:
    """``x`` minus its mean over the FORCE_PLATFORM:ZERO frames (module docstring)."""
    zero = parameter_values(analog.parameters, "FORCE_PLATFORM:ZERO")
    if zero is None or isinstance(zero, list) or len(zero) < 2 or not np.all(np.isfinite(zero[:2])):
        return x
    first, last = max(int(zero[0]), 1), min(int(zero[1]), analog.n_frames)
    if last < first:
        return x
    window = x[(first - 1) * analog.samples_per_frame:last * analog.samples_per_frame]
    finite = np.isfinite(window).all(axis=1)
    if not finite.any():
        notes.append(f"no baseline: NaN analog data in every ZERO frame {first}–{last}")
        return x
    return x - window[finite].mean(axis=0)


def _wrench(plate: _Plate, analog: AnalogData, metres: float) -> tuple[np.ndarray, np.ndarray]:
    """Action force F and moment M_C about the surface centre, plate coordinates, SI,
    at the analog rate: ``(n_samples, 3)`` each."""
    x = _baseline(analog, analog.values[:, plate.channels], plate.notes)
    kind = plate.type
    if kind == 4:
        w = x @ plate.cal.T
        f, m_o = w[:, :3], w[:, 3:] * metres
    else:
        x = x * np.array([analog.si_factor(c, k, metres, f"{role} of plate {plate.index + 1}")
                          for c, k, role in zip(plate.channels, CHANNEL_KINDS[kind],
                                                CHANNEL_NAMES[kind])])
    if kind == 1:
        f = x[:, 0:3]
        c = np.column_stack((x[:, 3], x[:, 4], np.zeros(len(x))))
        m_c = np.cross(c, f)
        m_c[:, 2] += x[:, 5]
        return f, m_c
    if kind == 2:
        f, m_o = x[:, 0:3], x[:, 3:6]
    elif kind == 3:
        (a, b), (fx12, fx34, fy14, fy23, fz1, fz2, fz3, fz4) = plate.ab, x.T
        f = np.column_stack((fx12 + fx34, fy14 + fy23, fz1 + fz2 + fz3 + fz4))
        m_o = np.column_stack((b * (fz1 + fz2 - fz3 - fz4), a * (-fz1 + fz2 + fz3 - fz4),
                               b * (-fx12 + fx34) + a * (fy14 - fy23)))
    return f, m_o - np.cross(plate.r, f)


def _push_sign(fz: np.ndarray, threshold_n: float) -> tuple[float, float, float]:
    """(sign, push, pull) of the plate-normal channel force ``fz (n,)`` N: ``sign`` +1
    when the channels hold the action on the plate (the subject pushes along +z), −1 when
    they hold the force on the subject; ``push`` and ``pull`` are the summed excursions
    beyond ``threshold_n`` of the side taken and of the other (N × samples).  With no
    excursion, +1 (the C3D description's action)."""
    fz = fz[np.isfinite(fz)]
    positive = float(np.sum(np.maximum(fz - threshold_n, 0.0)))
    negative = float(np.sum(np.maximum(-fz - threshold_n, 0.0)))
    if negative > positive:
        return -1.0, negative, positive
    return 1.0, positive, negative


def _lowpass(x: np.ndarray, cutoff_hz: float | None, rate: float) -> np.ndarray:
    """Zero-lag low-pass of ``x (n, m)`` per run of finite rows (module docstring)."""
    if cutoff_hz is None:
        return x
    sos = butter_lowpass_sos(FILTER_ORDER, cutoff_hz, rate)
    shortest = filtfilt_padlen(sos) + 1
    out = x.copy()
    for a, b in visible_segments(np.isfinite(x).all(axis=1)):
        if b - a >= shortest:
            out[a:b] = sosfiltfilt(sos, x[a:b])
    return out


def _check_magnitudes(analog: AnalogData, plate: _Plate, f: np.ndarray, m_c: np.ndarray) -> None:
    """C3DError at the first analog sample whose force ``f (n, 3)`` N or moment about the
    surface centre ``m_c (n, 3)`` N·m is beyond MAX_FORCE_N or MAX_MOMENT_N_M (NaN
    samples are flagged elsewhere)."""
    for what, values, limit, unit in (("force", f, MAX_FORCE_N, "N"), ("moment", m_c, MAX_MOMENT_N_M, "N m")):
        size = np.linalg.norm(values, axis=1)
        bad = np.flatnonzero(size > limit)
        if bad.size:
            k = int(bad[0])
            raise C3DError(f"{analog.source}: force plate FP{plate.index + 1}: a {what} of {size[k]:.3g} {unit} at "
                           f"t = {analog.time()[k]:g} s (analog sample {k + 1}): beyond {limit:.0e} {unit}, not a "
                           f"measurement (check the channels' ANALOG:SCALE, GEN_SCALE and units)")


def _cutoff(cutoff_hz, rate: str, analog: AnalogData) -> float | None:
    if rate not in ("point", "analog"):
        raise ValueError(f"rate must be 'point' or 'analog', got {rate!r}")
    cutoff = DEFAULT_CUTOFF_HZ if cutoff_hz is None else float(cutoff_hz)
    if cutoff == 0:
        return None
    nyquist = 0.5 * (analog.point_rate if rate == "point" else analog.rate)
    if not (np.isfinite(cutoff) and 0 < cutoff < nyquist):   # the file's rate is part of it: a C3DError
        key = "POINT:RATE" if rate == "point" else "ANALOG:RATE"
        raise C3DError(f"{analog.source}: cutoff_hz = {cutoff:g} Hz must be 0 (no filter) or "
                       f"positive and below {nyquist:g} Hz, half the {rate} rate ({key})")
    return cutoff


def read_force_plates(path: str | os.PathLike, threshold_n: float = DEFAULT_THRESHOLD_N,
                      cutoff_hz: float | None = None, rate: str = "point") -> list[ForcePlateData]:
    """Read every force plate of a C3D file (module docstring).

    Args:
        path: the C3D file (checked by :func:`~openfdk.io.c3d.inspect_c3d` first).
        threshold_n: plate-normal force (N, ≥ 0) above which a frame is loaded.
        cutoff_hz: zero-lag Butterworth cut-off, Hz; None: the markers' default (6 Hz);
            0: no filter.
        rate: ``'point'`` (the markers' frames) or ``'analog'`` (every analog sample).

    Returns: one :class:`ForcePlateData` per plate (empty when ``FORCE_PLATFORM:USED`` is
    0 or absent).  A plate never loaded is returned with a note, not refused.
    Raises: :class:`~openfdk.io.c3d.C3DError`, one line naming the file and the parameter.
    """
    if not (np.isfinite(threshold_n) and threshold_n >= 0):
        raise ValueError(f"threshold_n must be a finite number of newtons ≥ 0, got {threshold_n}")
    analog = read_analog(path)
    cutoff = _cutoff(cutoff_hz, rate, analog)
    used = parameter_values(analog.parameters, "FORCE_PLATFORM:USED")
    n_plates = 0 if used is None or isinstance(used, list) or not len(used) else int(used[0])
    if n_plates == 0:
        return []
    units = (analog.parameters.get("POINT:UNITS") or [""])[0].strip().lower()
    if units not in UNIT_TO_METRE and units:
        raise C3DError(f"{analog.source}: POINT:UNITS: {units!r}, expected mm, cm or m "
                       f"(the unit of FORCE_PLATFORM:CORNERS and ORIGIN)")
    metres = UNIT_TO_METRE[units or "mm"]
    plates = _plates(analog, n_plates, metres)
    if not units:
        _blank_units_as_mm(analog.source, plates)

    spf = analog.samples_per_frame
    step = spf if rate == "point" else 1
    time = analog.time()[::step]
    out_rate = analog.rate / step
    result = []
    for plate in plates:
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):   # NaN: flagged
            f, m_c = _wrench(plate, analog, metres)
            sign, push, pull = _push_sign(f[:, 2], threshold_n)
            if plate.rotation is None:
                if push > 0:
                    raise C3DError(plate.notes[0])
                peak = float(np.nanmax(np.abs(f[:, 2]), initial=0.0))
                warnings.warn(f"{plate.notes[0]}; FP{plate.index + 1} never carries more than "
                              f"{peak:.3g} N, so it is left out")
                continue
            _check_magnitudes(analog, plate, f, m_c)
            if sign < 0:
                plate.notes.append(
                    f"the channels hold the force on the subject (plate-normal force to "
                    f"{np.nanmin(f[:, 2]):.4g} N under load; {100 * push / (push + pull):.1f} % "
                    f"of its excursions beyond ±{threshold_n:g} N are negative): read with the "
                    f"sign reversed")
                f, m_c = -f, -m_c
            wrench = _lowpass(np.column_stack((f, m_c)), cutoff, analog.rate)[::step]
            f, m_c, fz = wrench[:, :3], wrench[:, 3:], wrench[:, 2]
            cx, cy = -m_c[:, 1] / fz, m_c[:, 0] / fz
            tz = m_c[:, 2] - (cx * f[:, 1] - cy * f[:, 0])
        bad = ~np.isfinite(analog.values[:, plate.channels]).all(axis=1)
        invalid = bad.reshape(-1, step).any(axis=1)
        loaded = (fz > threshold_n) & ~invalid & np.isfinite(wrench).all(axis=1)
        cop = np.column_stack((cx, cy, np.zeros_like(cx)))
        cop[~loaded] = np.nan
        tz[~loaded] = np.nan
        R, centre = plate.rotation, plate.corners.mean(axis=0)
        if bad.any():
            plate.notes.append(f"{int(invalid.sum())} of {len(invalid)} samples with NaN "
                               f"analog data flagged invalid (not loaded)")
        if not loaded.any():
            plate.notes.append(f"never loaded: plate-normal force never above {threshold_n:g} N")
        arrays = dict(
            force=-f @ R.T, moment=-(m_c + np.cross(plate.r, f)) @ R.T,
            cop=centre + cop @ R.T, free_moment=-tz[:, None] * R[:, 2],
            time=time, loaded=loaded, invalid=invalid, corners=plate.corners,
            origin=centre - R @ plate.r, rotation=R)
        for value in arrays.values():
            value.setflags(write=False)
        result.append(ForcePlateData(
            name=f"FP{plate.index + 1}", type=plate.type, rate=out_rate,
            threshold_n=float(threshold_n), cutoff_hz=cutoff, notes=tuple(plate.notes), **arrays))
    return result
