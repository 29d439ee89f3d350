"""Analog channels of a C3D file, read in pure Python (numpy), for the force plates.

Why not ezc3d: the file is first checked by :func:`openfdk.io.c3d.inspect_c3d` (header,
parameter records, the data section fits in the file), after which decoding the data
section is a few numpy calls (≈ 1 ms for 10 s of 24 channels at 1 kHz, against ≈ 30 ms
for ``ezc3d.c3d``), cannot crash the process, reads big-endian (MIPS) files, which ezc3d
cannot, and applies ``ANALOG:OFFSET`` with its sign (ezc3d 1.5–1.7 subtracts
``|OFFSET|``: ``AnalogsInfo.cpp``, ``offset = abs(offset)``).

Layout (C3D User Guide, "The 3D Point Data Section", "The ANALOG group"): per 3D frame,
4 values per point (x, y, z, residual word), then ``samples_per_frame`` analog samples
of ``ANALOG:USED`` channels each, channel 1 first; float32 values in float files
(header scale < 0), int16 otherwise (uint16 when ``ANALOG:FORMAT`` is ``UNSIGNED``).
The counts come from the parameters where present, as ezc3d does (``POINT:USED``,
``POINT:FRAMES``, ``POINT:DATA_START``, ``ANALOG:USED``, ``ANALOG:RATE``), else from the
header; ``samples_per_frame = ANALOG:RATE / POINT:RATE`` must be a whole number and agree
with the header's analog values per frame (header word 3).

A channel's value, in its ``ANALOG:UNITS`` (:meth:`AnalogData.si_factor` converts the
force, moment and length units to SI):

    value = (stored − ANALOG:OFFSET) × ANALOG:SCALE × ANALOG:GEN_SCALE

Sample ``j`` (0-based) of file frame ``k`` is at time
``(first_frame − 1 + k) / POINT:RATE + j / ANALOG:RATE``: the first sample of a frame
is taken with the frame (its time is the marker sample's time).

The parameters come from :func:`~openfdk.io.c3d.inspect_c3d` (flat arrays in file
order: the first C3D index varies fastest); :func:`read_analog` adds their dimensions,
which the force plates need (``FORCE_PLATFORM:CHANNEL`` is ``(channels per plate,
plates)``, ``CAL_MATRIX`` ``(rows, columns, plates)``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from openfdk.io.c3d import (
    BLOCK_BYTES,
    C3DError,
    _as_count,
    _decode_floats,
    _first_number,
    _int8,
    _int_dtype,
    _is_continuation,
    inspect_c3d,
)

__all__ = ["AnalogData", "read_analog", "parameter_values"]

PROCESSOR_CODES = {"Intel": 84, "DEC": 85, "MIPS": 86}
#: ANALOG:UNITS → SI factor, keys lower case without spaces, dots, dashes or ·
SI_UNITS = {"force": {"n": 1.0, "kn": 1e3},
            "moment": {"nmm": 1e-3, "ncm": 1e-2, "nm": 1.0, "knm": 1e3},
            "length": {"mm": 1e-3, "cm": 1e-2, "m": 1.0}}
SI_UNIT_NAMES = {"force": "N, kN", "moment": "N·mm, N·cm, N·m, kN·m", "length": "mm, cm, m"}


@dataclass(frozen=True, eq=False)
class AnalogData:
    """The analog channels of a C3D file and its parameters.

    Attributes:
        source: the file, named in every error.
        labels, units: ``ANALOG:LABELS`` / ``ANALOG:UNITS`` per channel (stripped; ``""``
            where the file has none).
        values: ``(n_samples, n_channels)`` scaled values (module docstring), in each
            channel's ``ANALOG:UNITS``; NaN where the file stores NaN.
        rate: ``ANALOG:RATE``, Hz; ``point_rate``: ``POINT:RATE``, Hz.
        samples_per_frame: analog samples per 3D frame (``rate / point_rate``).
        first_frame: the file's first frame (1-based); ``n_frames``: 3D frames.
        parameters: ``"GROUP:NAME"`` → value, as :func:`~openfdk.io.c3d.inspect_c3d`
            decodes them (list of str, or a flat float array).
        dims: ``"GROUP:NAME"`` → the parameter's dimensions (``()`` for a scalar).
    """

    source: str
    labels: tuple[str, ...]
    units: tuple[str, ...]
    values: np.ndarray
    rate: float
    point_rate: float
    samples_per_frame: int
    first_frame: int
    n_frames: int
    parameters: dict
    dims: dict

    @property
    def n_channels(self) -> int:
        return self.values.shape[1]

    def si_factor(self, channel: int, kind: str, metres: float, role: str) -> float:
        """SI factor of channel ``channel`` (0-based) measuring a ``kind`` ("force",
        "moment", "length") from its ``ANALOG:UNITS``; a blank unit is the C3D default
        (N, N·POINT:UNITS, POINT:UNITS; ``metres``: one point unit in m).  Another unit
        is a C3DError naming the channel and its ``role``."""
        unit = self.units[channel]
        key = "".join(ch for ch in unit.lower() if ch not in " .-*·•⋅_")
        if not key:
            return {"force": 1.0, "moment": metres, "length": metres}[kind]
        table = SI_UNITS[kind]
        if key not in table:
            raise C3DError(f"{self.source}: ANALOG:UNITS: channel {channel + 1} ({role}) is "
                           f"{unit!r}, expected a {kind} unit: {SI_UNIT_NAMES[kind]}")
        return table[key]

    def time(self) -> np.ndarray:
        """``(n_samples,)`` s, the time of every analog sample."""
        k = np.arange(self.values.shape[0])
        return (self.first_frame - 1) / self.point_rate + k / self.rate


def parameter_values(parameters: dict, key: str) -> list | np.ndarray | None:
    """A parameter joined with its continuations (``SCALE``, ``SCALE2``, ``SCALE3``, …),
    or None when absent."""
    parts = sorted(((int(k[len(key):] or 1), v) for k, v in parameters.items()
                    if _is_continuation(k, key)), key=lambda item: item[0])
    if not parts:
        return None
    if all(isinstance(v, list) for _, v in parts):
        return [s for _, v in parts for s in v]
    return np.concatenate([np.asarray(v, dtype=float).reshape(-1) for _, v in parts
                           if not isinstance(v, list)])


def _parameter_dims(name: str, parameter_block: int, processor: int) -> dict:
    """``"GROUP:NAME"`` → dimensions of every parameter.  The records were checked by
    ``inspect_c3d`` (packed, inside the file), so this walk only reads them."""
    with open(name, "rb") as f:
        f.seek((parameter_block - 1) * BLOCK_BYTES)
        buf = f.read(255 * BLOCK_BYTES)
    offset_dtype = _int_dtype(processor, signed=False)
    groups: dict[int, str] = {}
    found: list[tuple[int, str, tuple[int, ...]]] = []
    pos = 4
    while pos + 2 <= len(buf):
        n_name, item_id = _int8(buf[pos]), _int8(buf[pos + 1])
        if n_name == 0:
            break
        offset_pos = pos + 2 + abs(n_name)
        item = bytes(buf[pos + 2:offset_pos]).decode("latin-1").strip().upper()
        offset = int(np.frombuffer(buf, dtype=offset_dtype, count=1, offset=offset_pos)[0])
        if item_id < 0:
            groups[-item_id] = item
        else:
            n_dims = buf[offset_pos + 3]
            found.append((item_id, item, tuple(buf[offset_pos + 4:offset_pos + 4 + n_dims])))
        if offset == 0:
            break
        pos = offset_pos + offset
    return {f"{groups.get(g, f'GROUP{g}')}:{item}": dims for g, item, dims in found}


def _per_channel(parameters: dict, key: str, n: int, default, name: str):
    values = parameter_values(parameters, key)
    if isinstance(default, str) and values is not None and not isinstance(values, list):
        values = None                                   # numbers where text belongs: unnamed
    if values is None or len(values) == 0:
        return [default] * n if isinstance(default, str) else np.full(n, float(default))
    if len(values) < n:
        raise C3DError(f"{name}: {key}: {len(values)} values for {n} analog channels")
    return values[:n]


def read_analog(path: str | os.PathLike) -> AnalogData:
    """Read every analog channel of a C3D file (module docstring).

    Raises :class:`~openfdk.io.c3d.C3DError` (one line naming the file) when the file
    fails :func:`~openfdk.io.c3d.inspect_c3d` or its analog layout is inconsistent.
    """
    name = os.fspath(path)
    try:
        layout = inspect_c3d(name)
    except C3DError as exc:
        message = str(exc)
        if message.isprintable():
            raise
        # its message quotes the raw bytes of a corrupt name: keep it on one line
        raise C3DError("".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in message)
                       ) from None
    parameters = layout.parameters
    processor = PROCESSOR_CODES[layout.processor]
    point_rate = _first_number(parameters, "POINT:RATE") or layout.rate
    if not point_rate > 0 and layout.analog_samples_per_frame:
        # no 3D points and no frame rate (a force-only Kistler BioWare file): the frame is
        # the header's analog samples per frame (word 10)
        point_rate = (_first_number(parameters, "ANALOG:RATE") or 0.0) / layout.analog_samples_per_frame
    if not (np.isfinite(point_rate) and point_rate > 0):
        raise C3DError(f"{name}: no frame rate: POINT:RATE, the header's rate and "
                       f"ANALOG:RATE are not positive")
    n_points = _as_count(_first_number(parameters, "POINT:USED"))
    n_points = layout.n_points if n_points is None else n_points
    n_frames = _as_count(_first_number(parameters, "POINT:FRAMES")) or layout.n_frames
    start_block = _as_count(_first_number(parameters, "POINT:DATA_START")) or layout.data_start_block

    header_channels = (layout.n_analog_values // layout.analog_samples_per_frame
                       if layout.analog_samples_per_frame else 0)
    n_channels = _as_count(_first_number(parameters, "ANALOG:USED"))
    n_channels = header_channels if n_channels is None else n_channels
    analog_rate = _first_number(parameters, "ANALOG:RATE") or \
        point_rate * max(layout.analog_samples_per_frame, 1)
    ratio = analog_rate / point_rate
    samples = int(round(ratio)) if np.isfinite(ratio) else 0
    if n_channels and (samples < 1 or abs(ratio - samples) > 1e-6 * ratio):
        raise C3DError(f"{name}: ANALOG:RATE: {analog_rate:g} Hz is not a whole multiple of "
                       f"POINT:RATE {point_rate:g} Hz")
    if n_channels and layout.n_analog_values != n_channels * samples:
        raise C3DError(f"{name}: ANALOG:USED: {n_channels} channels × {samples} samples per "
                       f"frame disagree with the header's {layout.n_analog_values} analog "
                       f"values per frame")

    labels = [s.strip() for s in _per_channel(parameters, "ANALOG:LABELS", n_channels, "", name)]
    units = [s.strip() for s in _per_channel(parameters, "ANALOG:UNITS", n_channels, "", name)]
    scale = _per_channel(parameters, "ANALOG:SCALE", n_channels, 1.0, name)
    offset = _per_channel(parameters, "ANALOG:OFFSET", n_channels, 0.0, name)
    gen_scale = _first_number(parameters, "ANALOG:GEN_SCALE")
    gen_scale = 1.0 if gen_scale is None else gen_scale
    data_format = parameters.get("ANALOG:FORMAT")
    unsigned = (isinstance(data_format, list)
                and [v.strip().upper() for v in data_format[:1]] == ["UNSIGNED"])

    value_bytes = 4 if layout.is_float else 2
    per_frame = 4 * n_points + n_channels * samples
    with open(name, "rb") as f:
        f.seek((start_block - 1) * BLOCK_BYTES)
        raw = f.read(n_frames * per_frame * value_bytes)
    if len(raw) < n_frames * per_frame * value_bytes:      # inspect_c3d checked this
        raise C3DError(f"{name} is truncated: the data section ends early")
    if layout.is_float:
        stored = _decode_floats(raw, processor)
    else:
        stored = np.frombuffer(raw, dtype=_int_dtype(processor, signed=not unsigned)).astype(float)
    stored = stored.reshape(n_frames, per_frame)[:, 4 * n_points:]
    stored = stored.reshape(n_frames * samples, n_channels)
    with np.errstate(invalid="ignore", over="ignore"):
        values = (stored - offset) * (scale * gen_scale)
    values.setflags(write=False)
    return AnalogData(
        source=name, labels=tuple(labels), units=tuple(units), values=values,
        rate=float(analog_rate), point_rate=float(point_rate), samples_per_frame=samples,
        first_frame=max(layout.first_frame, 1), n_frames=n_frames, parameters=parameters,
        dims=_parameter_dims(name, layout.parameter_block, processor))
