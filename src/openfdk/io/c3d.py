"""C3D marker files: a validating reader and a writer (ezc3d behind a safety check).

What is read: the 3D points of a C3D file (labels, positions, residuals, point rate,
first frame, ``POINT:UNITS``); analog channels, force plates and events are ignored.
Positions are converted once, at this boundary, to metres (docs/design.md §4).

Safety: ezc3d is a C++ library and can crash the whole Python process on a malformed
file (docs/design.md §5), which no ``try`` can catch.  :func:`read_c3d` therefore first checks
the file in pure Python (:func:`inspect_c3d`) — header block, parameter section, and
that the file is long enough for the data the header and parameters promise — and only
then hands it to ezc3d.  Every problem is raised as :class:`C3DError` naming the file.

C3D layout used by the check (C3D User Guide, "The Header Section", "The Parameter
Section", "The 3D Point Data Section"); 512-byte blocks are numbered from 1, a "word"
is 16 bits:

* header word 1: byte 1 = block of the parameter section, byte 2 = 0x50 ('P');
  word 2 = 3D points per frame; word 3 = analog values per 3D frame (channels ×
  samples per frame); words 4/5 = first/last frame (1-based); words 7–8 = float scale
  factor, **negative ⇒ data stored as float32**, positive ⇒ int16 × scale;
  word 9 = first block of the data section; word 10 = analog samples per 3D frame;
  words 11–12 = float point rate (Hz).
* parameter section: byte 3 = number of parameter blocks, byte 4 = processor type
  83 + (1 Intel little-endian IEEE, 2 DEC little-endian words with VAX floats,
  3 MIPS/SGI big-endian), then group/parameter records chained by 16-bit offsets.
* data section: per frame, 4 values per point (x, y, z, residual word) then the analog
  values; 4 bytes per value in float format, 2 in integer format.
"""

from __future__ import annotations

import difflib
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import ezc3d
import numpy as np

__all__ = ["C3DError", "C3DLayout", "MarkerTrial", "MissingMarkerError", "inspect_c3d",
           "read_c3d", "write_c3d"]

BLOCK_BYTES = 512
PROCESSOR_NAMES = {84: "Intel", 85: "DEC", 86: "MIPS"}
UNIT_TO_METRE = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


def _duplicates(labels: Sequence[str]) -> list[str]:
    return sorted({label for label in labels if labels.count(label) > 1})


class C3DError(ValueError):
    """A C3D file cannot be read or written; the message names the file and the cause."""


class MissingMarkerError(ValueError):
    """Markers requested by name are not in a trial.

    Attributes: ``missing`` (tuple of labels), ``source`` (file), ``available`` (labels).
    """

    def __init__(self, message: str, missing: Sequence[str], source: str,
                 available: Sequence[str]):
        super().__init__(message)
        self.missing = tuple(missing)
        self.source = source
        self.available = tuple(available)


# --------------------------------------------------------------------------------------
# The trial
# --------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class MarkerTrial:
    """Measured marker positions of one trial, in SI units.

    Attributes:
        labels: marker names (whitespace stripped, unique), length n_markers.
        rate: sample rate, Hz.
        time: ``(n_frames,)`` s, sample times.  For a C3D file,
            ``time[k] = (first_frame − 1 + k) / rate`` with the file's 1-based first frame,
            so a normal file (first frame 1) starts at t = 0 and a cropped file keeps
            its times in the original recording.
        positions: ``(n_frames, n_markers, 3)`` m, NaN where a sample is missing.
        source: where the data came from (file path), used in error messages.
    """

    labels: tuple[str, ...]
    rate: float
    time: np.ndarray
    positions: np.ndarray
    source: str = "<memory>"
    _index: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        labels = tuple(str(label) for label in self.labels)
        time = np.array(self.time, dtype=float).reshape(-1)
        positions = np.array(self.positions, dtype=float)
        rate = float(self.rate)
        if not (np.isfinite(rate) and rate > 0):
            raise ValueError(f"{self.source}: rate must be a positive number of Hz, got {rate}")
        if positions.ndim != 3 or positions.shape[1:] != (len(labels), 3):
            raise ValueError(
                f"{self.source}: positions must have shape (n_frames, {len(labels)}, 3) "
                f"for {len(labels)} labels, got {positions.shape}")
        if time.shape != (positions.shape[0],):
            raise ValueError(f"{self.source}: time must have shape ({positions.shape[0]},), "
                             f"got {time.shape}")
        if _duplicates(labels):
            raise ValueError(f"{self.source}: duplicate marker labels {_duplicates(labels)}")
        time.setflags(write=False)
        positions.setflags(write=False)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "rate", rate)
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "_index", {lab: i for i, lab in enumerate(labels)})

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_markers(self) -> int:
        return self.positions.shape[1]

    def _near_matches(self, label: str) -> list[str]:
        lower = {lab.lower(): lab for lab in self.labels}
        hits = difflib.get_close_matches(label.lower(), list(lower), n=3, cutoff=0.6)
        return [lower[h] for h in hits]

    def index(self, label: str) -> int:
        """Column of marker ``label`` in ``positions``; :class:`MissingMarkerError` if absent."""
        try:
            return self._index[label]
        except KeyError:
            near = self._near_matches(label)
            hint = f"; did you mean {', '.join(repr(n) for n in near)}?" if near else ""
            raise MissingMarkerError(
                f"marker {label!r} missing from {self.source}{hint} "
                f"(available: {', '.join(self.labels)})",
                [label], self.source, self.labels) from None

    def select(self, labels: Sequence[str], optional: Sequence[str] = ()) -> MarkerTrial:
        """The trial restricted to ``labels``, in that order; a label of ``optional`` (a
        marker the analysis does not track, weight 0) absent from the file is an all-NaN
        column (never visible).

        Raises :class:`MissingMarkerError` naming every missing label, the file and the
        labels available.
        """
        labels = [str(lab) for lab in labels]
        optional = {str(lab) for lab in optional}
        missing = [lab for lab in labels if lab not in self._index and lab not in optional]
        if missing:
            hints = [f"{lab!r} ~ {', '.join(repr(n) for n in self._near_matches(lab))}"
                     for lab in missing if self._near_matches(lab)]
            hint = f"; near matches: {'; '.join(hints)}" if hints else ""
            raise MissingMarkerError(
                f"{len(missing)} marker(s) missing from {self.source}: "
                f"{', '.join(repr(m) for m in missing)}{hint}. "
                f"Available: {', '.join(self.labels)}",
                missing, self.source, self.labels)
        columns = [self._index.get(lab, -1) for lab in labels]
        positions = self.positions[:, [max(c, 0) for c in columns], :].copy() if self.positions.size else \
            np.full((self.n_frames, len(labels), 3), np.nan)
        positions[:, [k for k, c in enumerate(columns) if c < 0], :] = np.nan
        return MarkerTrial(labels=tuple(labels), rate=self.rate, time=self.time,
                           positions=positions, source=self.source)


# --------------------------------------------------------------------------------------
# Pure-Python inspection of header and parameter section (no ezc3d)
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class C3DLayout:
    """What the header and parameter section of a C3D file promise.

    Counts are the ones implied by the header; ``parameters`` maps ``"GROUP:NAME"`` to
    the decoded value (list of str for character parameters, 1-D ndarray otherwise).
    """

    processor: str
    parameter_block: int
    n_points: int
    n_analog_values: int          # analog values per 3D frame (header word 3)
    analog_samples_per_frame: int
    first_frame: int              # 1-based (header word 4)
    n_frames: int
    is_float: bool
    data_start_block: int
    rate: float                   # Hz (header words 11–12)
    file_size: int
    parameters: dict


def _decode_floats(raw: bytes, processor: int) -> np.ndarray:
    """float32 values stored by ``processor`` → float64 array."""
    if processor == 85:            # DEC: 16-bit halves swapped, VAX F value = IEEE value / 4
        swapped = np.frombuffer(raw, dtype=np.uint8).reshape(-1, 4)[:, [2, 3, 0, 1]].copy()
        return swapped.view("<f4").reshape(-1).astype(float) / 4.0
    return np.frombuffer(raw, dtype=(">f4" if processor == 86 else "<f4")).astype(float)


def _text(raw: bytes) -> str:
    """A character parameter's entry: up to its first NUL (Kistler BioWare pads units
    as ``N\\0``), blanks stripped."""
    return raw.split(b"\x00", 1)[0].decode("latin-1").strip()


def _int8(byte: int) -> int:
    """A byte read as a signed 8-bit integer."""
    return byte - 256 if byte > 127 else byte


def _int_dtype(processor: int, signed: bool) -> str:
    return (">" if processor == 86 else "<") + ("i2" if signed else "u2")


def _parse_parameters(buf: bytes, processor: int, name: str) -> dict:
    """Decode the group/parameter records of a parameter section.

    ``buf`` starts at the parameter section (its 4-byte preamble included).  Record
    format (C3D User Guide, "Group Format", "Parameter Format"): int8 name length
    (negative = locked, 0 = end), int8 id (negative = group, positive = parameter of
    group |id|), name, 16-bit offset to the next record counted from the offset field
    (0 = last record), then for a group: uint8 description length, description; for a
    parameter: int8 type (−1 char, 1 byte, 2 int16, 4 float), uint8 number of
    dimensions (≤ 7), the dimensions (uint8 each), the data, the description.

    Stricter than the format, as ezc3d is: records must be packed (each offset points
    just past its record's description) and no group id may be defined twice.
    """
    group_names: dict[int, str] = {}
    raw_params: list[tuple[int, str, object]] = []
    offset_dtype = _int_dtype(processor, signed=False)
    pos = 4
    while True:
        if pos + 2 > len(buf):
            raise C3DError(f"{name}: parameter section is corrupt: its records run past "
                           f"the end of the file")
        n_name, item_id = _int8(buf[pos]), _int8(buf[pos + 1])
        if n_name == 0:
            break
        offset_pos = pos + 2 + abs(n_name)
        item_name = bytes(buf[pos + 2:offset_pos]).decode("latin-1").strip().upper()
        group = group_names.get(abs(item_id), f"group {abs(item_id)}")
        label = f"group {item_name}" if item_id < 0 else f"parameter {group}:{item_name}"

        def corrupt(what, label=label, pos=pos):
            return C3DError(f"{name}: parameter section is corrupt at {label} (byte {pos} "
                            f"of the section): {what}")

        if item_id == 0:
            raise corrupt("group id 0")
        if not item_name.isprintable():
            raise corrupt("the name is not printable text")
        if offset_pos + (3 if item_id < 0 else 4) > len(buf):
            raise corrupt("the record runs past the end of the file")
        offset = int(np.frombuffer(buf, dtype=offset_dtype, count=1, offset=offset_pos)[0])
        if item_id < 0:
            if -item_id in group_names:
                raise corrupt(f"group id {-item_id} is already {group_names[-item_id]}")
            group_names[-item_id] = item_name
            record_end = offset_pos + 3 + buf[offset_pos + 2]
        else:
            head = offset_pos + 2
            data_type, n_dims = _int8(buf[head]), buf[head + 1]
            if data_type not in (-1, 1, 2, 4):
                raise corrupt(f"unknown data type {data_type}")
            if n_dims > 7:                                 # the C3D limit
                raise corrupt(f"{n_dims} dimensions (at most 7)")
            dims = list(buf[head + 2:head + 2 + n_dims])
            data_pos = head + 2 + n_dims
            n_values = math.prod(dims)                     # 1 for a scalar (no dims)
            data_end = data_pos + abs(data_type) * n_values
            if data_end + 1 > len(buf):
                raise corrupt("the data run past the end of the file")
            record_end = data_end + 1 + buf[data_end]
            raw = bytes(buf[data_pos:data_end])
            if data_type == -1 and n_dims <= 1:
                value = [_text(raw)]
            elif data_type == -1:                          # dims[0] = string length
                width = dims[0]
                value = [_text(raw[i * width:(i + 1) * width])
                         for i in range(n_values // width if width else 0)]
            elif data_type == 1:
                value = np.frombuffer(raw, dtype=np.uint8).astype(float)
            elif data_type == 2:
                value = np.frombuffer(raw, dtype=_int_dtype(processor, True)).astype(float)
            else:
                value = _decode_floats(raw, processor)
            raw_params.append((item_id, item_name, value))
        if record_end > len(buf):
            raise corrupt("the description runs past the end of the file")
        if offset == 0:
            break
        if offset_pos + offset != record_end:
            raise corrupt(f"the pointer to the next record ({offset_pos + offset}) is not "
                          f"the end of this record ({record_end})")
        pos = record_end
    parameters = {}
    for group_id, param_name, value in raw_params:
        group = group_names.get(group_id, f"GROUP{group_id}")
        parameters[f"{group}:{param_name}"] = value
    return parameters


_SCALAR_NUMERIC_PARAMETERS = (
    "POINT:USED", "POINT:FRAMES", "POINT:RATE", "POINT:SCALE", "POINT:DATA_START",
    "ANALOG:USED", "ANALOG:RATE", "ANALOG:GEN_SCALE", "FORCE_PLATFORM:USED",
    "ROTATION:USED", "ROTATION:DATA_START", "ROTATION:RATE", "ROTATION:RATIO",
)


#: parameters ezc3d interprets as numbers (any length)
_NUMERIC_PARAMETERS = frozenset(_SCALAR_NUMERIC_PARAMETERS + (
    "ANALOG:SCALE", "ANALOG:OFFSET", "ANALOG:BITS", "FORCE_PLATFORM:TYPE", "FORCE_PLATFORM:ZERO",
    "FORCE_PLATFORM:CORNERS", "FORCE_PLATFORM:ORIGIN", "FORCE_PLATFORM:CHANNEL", "FORCE_PLATFORM:CAL_MATRIX",
))


def _is_continuation(key: str, base: str) -> bool:
    """``key`` is ``base`` or one of its continuations ``base2``, ``base3``, …"""
    return key == base or (key.startswith(base) and key[len(base):].isdigit())


def _first_number(parameters: dict, key: str) -> float | None:
    value = parameters.get(key)
    if value is None or isinstance(value, list) or len(value) == 0:
        return None
    return float(value[0])


def _as_count(value: float | None) -> int | None:
    """A C3D count stored in a signed int16 (values above 32767 appear negative)."""
    if value is None:
        return None
    value = int(value)
    return value + 65536 if value < 0 else value


def inspect_c3d(path: str | os.PathLike) -> C3DLayout:
    """Check a C3D file's structure in pure Python, before any C++ reader touches it.

    Checks: the file exists and is non-empty; the 512-byte header is complete; byte 2
    is 0x50; the parameter block pointer (byte 1) points inside the file; the processor
    type is 84 (Intel), 85 (DEC) or 86 (MIPS); the parameter records are well formed
    (packed, ≤ 7 dimensions, no group id twice; counts and rates finite and ≥ 0; labels
    and units are text; enough labels for the points); the header and POINT:SCALE agree
    on float vs integer storage; ANALOG:SCALE, ANALOG:OFFSET and ANALOG:GEN_SCALE cover
    every analog channel (ezc3d crashes otherwise); the data section implied by the
    header and by the parameters (data start block + frames × (4 × points + analog
    values) × 2 or 4 bytes), and ezc3d's ROTATION data, fit in the file.
    Returns the layout; raises :class:`C3DError` naming the file otherwise.
    """
    name = os.fspath(path)
    if not os.path.exists(name):
        raise C3DError(f"{name}: no such C3D file")
    if not os.path.isfile(name):
        raise C3DError(f"{name}: not a file")
    file_size = os.path.getsize(name)
    if file_size == 0:
        raise C3DError(f"{name}: the file is empty")
    from .placeholders import placeholder_of_file

    if (why := placeholder_of_file(name)) is not None:
        raise C3DError(f"{name}: {why}")
    if file_size < BLOCK_BYTES:
        raise C3DError(f"{name}: not a C3D file: only {file_size} bytes, a C3D header "
                       f"alone is {BLOCK_BYTES} bytes")
    with open(name, "rb") as f:
        header = f.read(BLOCK_BYTES)
        parameter_block = header[0]
        if header[1] != 0x50:
            raise C3DError(f"{name}: not a C3D file: byte 2 is 0x{header[1]:02X}, "
                           f"expected 0x50")
        parameter_start = (parameter_block - 1) * BLOCK_BYTES
        if parameter_block < 2 or parameter_start + 4 > file_size:
            raise C3DError(f"{name}: not a valid C3D file: parameter section pointer "
                           f"(byte 1) is block {parameter_block}, the file has "
                           f"{file_size // BLOCK_BYTES} whole blocks")
        f.seek(parameter_start)
        # 255 blocks is the largest parameter section a one-byte block count can declare
        section = f.read(255 * BLOCK_BYTES)
    processor = section[3]
    if processor not in PROCESSOR_NAMES:
        raise C3DError(f"{name}: unknown processor type {processor} in the parameter "
                       f"section (expected 84 Intel, 85 DEC or 86 MIPS)")

    words = np.frombuffer(header[2:24], dtype=_int_dtype(processor, signed=False))
    n_points = int(words[0])                                     # word 2
    n_analog_values = int(words[1])                              # word 3
    first_frame, last_frame = int(words[2]), int(words[3])       # words 4, 5
    scale_factor = float(_decode_floats(header[12:16], processor)[0])   # words 7–8
    data_start_block = int(words[7])                             # word 9
    analog_samples_per_frame = int(words[8])                     # word 10
    rate = float(_decode_floats(header[20:24], processor)[0])    # words 11–12
    # first frame is 1-based; some writers put 0 (then last frame is 0-based too)
    n_frames = (last_frame - first_frame + 1) if (n_points or n_analog_values) else 0
    if n_frames < 0:
        raise C3DError(f"{name}: header last frame {last_frame} is before first frame "
                       f"{first_frame}")
    is_float = scale_factor < 0

    parameters = _parse_parameters(section, processor, name)
    # ezc3d dereferences the first value of these parameters without a check: they
    # must hold at least one value of the right kind when present
    for key in _SCALAR_NUMERIC_PARAMETERS:
        value = parameters.get(key)
        if value is not None and (isinstance(value, list) or len(value) == 0
                                  or not np.isfinite(value[0])
                                  or (value[0] < 0 and key != "POINT:SCALE")):
            raise C3DError(f"{name}: parameter {key} must hold a finite "
                           f"{'' if key == 'POINT:SCALE' else 'non-negative '}number, "
                           f"found {value!r}")

    for key, value in parameters.items():
        if (key == "POINT:UNITS" or _is_continuation(key, "POINT:LABELS")) and not isinstance(
                value, list):
            raise C3DError(f"{name}: parameter {key} must hold text, found numbers {value!r}")
        # ezc3d reads these as numbers whenever present: text there crashes the process
        # (found by the fuzz suite: FORCE_PLATFORM:CHANNEL stored as characters)
        if key in _NUMERIC_PARAMETERS and isinstance(value, list):
            raise C3DError(f"{name}: parameter {key} must hold numbers, found text {value!r}")

    # the parameters describe the data too (and win where they differ, C3D User Guide);
    # where one is absent, the header value stands
    param_points = _as_count(_first_number(parameters, "POINT:USED"))
    param_points = n_points if param_points is None else param_points
    param_frames = _as_count(_first_number(parameters, "POINT:FRAMES")) or n_frames
    param_rate = _first_number(parameters, "POINT:RATE")
    param_rate = rate if param_rate is None else param_rate
    param_start = _as_count(_first_number(parameters, "POINT:DATA_START")) or data_start_block
    param_scale = _first_number(parameters, "POINT:SCALE")
    if param_scale is not None and (param_scale < 0) != is_float:
        raise C3DError(f"{name}: header scale factor {scale_factor:g} and POINT:SCALE "
                       f"{param_scale:g} disagree on float vs integer storage")
    if n_points == 0 and param_points == 0 and not (n_analog_values or
                                                    _first_number(parameters, "ANALOG:USED")):
        raise C3DError(f"{name}: contains no 3D points and no analog data (header and "
                       f"POINT:USED say 0 points)")
    if (n_points or param_points) and not (np.isfinite(param_rate) and param_rate > 0):
        raise C3DError(f"{name}: point rate is {param_rate}, expected a positive rate in Hz")

    labels = [lab for key, value in parameters.items() if _is_continuation(key, "POINT:LABELS")
              and isinstance(value, list) for lab in value]
    if max(n_points, param_points) > len(labels):
        raise C3DError(f"{name}: POINT:LABELS lists {len(labels)} labels for "
                       f"{max(n_points, param_points)} points")

    # analog channels: ezc3d indexes ANALOG:SCALE/OFFSET per channel, so short arrays
    # would make it read out of bounds (a crash, not an exception)
    n_channels = (n_analog_values // analog_samples_per_frame
                  if analog_samples_per_frame else 0)
    param_channels = _as_count(_first_number(parameters, "ANALOG:USED"))
    analog_rate = _first_number(parameters, "ANALOG:RATE")
    param_samples = (round(analog_rate / param_rate) if analog_rate and param_rate > 0
                     else analog_samples_per_frame)
    channels_needed = max(n_channels, param_channels or 0)
    if channels_needed and not any(k.startswith("SHADOW:") for k in parameters):
        if _first_number(parameters, "ANALOG:GEN_SCALE") is None:
            raise C3DError(f"{name}: {channels_needed} analog channels but ANALOG:GEN_SCALE "
                           f"is missing")
        for key in ("ANALOG:SCALE", "ANALOG:OFFSET"):
            n_values = sum(len(v) for k, v in parameters.items()
                           if _is_continuation(k, key))
            if n_values < channels_needed:
                raise C3DError(f"{name}: {key} has {n_values} values for "
                               f"{channels_needed} analog channels")

    # the data section must fit in the file, both as the header and as the parameters
    # describe it (ezc3d trusts the parameters where they differ)
    value_bytes = 4 if is_float else 2
    layouts = [
        ("header", n_frames, n_points, n_analog_values, data_start_block),
        ("parameters", param_frames, param_points, (param_channels or 0) * param_samples,
         param_start),
    ]
    parameter_end = parameter_start + BLOCK_BYTES
    for source, frames, points, analog_values, start_block in layouts:
        data_start = (start_block - 1) * BLOCK_BYTES
        if frames and (start_block < 2 or data_start < parameter_end):
            raise C3DError(f"{name}: data start block {start_block} (from the {source}) "
                           f"does not follow the parameter section at block "
                           f"{parameter_block}")
        data_bytes = frames * (4 * points + analog_values) * value_bytes
        if data_start + data_bytes > file_size:
            analog = f" and {analog_values} analog values" if analog_values else ""
            raise C3DError(
                f"{name} is truncated: {source} promises {frames} frames of {points} "
                f"points{analog} ({data_bytes} bytes of data from block {start_block}) "
                f"but the file ends after {file_size} bytes")

    # ezc3d's ROTATION extension: 4×4 matrix + reliability (17 floats) per rotation per
    # subframe from ROTATION:DATA_START; reading past the end aborts the process
    n_rotations = _as_count(_first_number(parameters, "ROTATION:USED")) or 0
    if n_rotations:
        ratio = _first_number(parameters, "ROTATION:RATIO")
        rotation_rate = _first_number(parameters, "ROTATION:RATE")
        if not ratio and rotation_rate:
            ratio = rotation_rate / param_rate
        ratio = round(ratio or 0)
        start_block = _as_count(_first_number(parameters, "ROTATION:DATA_START")) or 0
        rotation_bytes = param_frames * ratio * n_rotations * 17 * 4
        if ratio < 1:
            raise C3DError(f"{name}: {n_rotations} rotations but no positive "
                           f"ROTATION:RATIO or ROTATION:RATE")
        if start_block < 2 or (start_block - 1) * BLOCK_BYTES + rotation_bytes > file_size:
            raise C3DError(
                f"{name} is truncated: ROTATION parameters promise {param_frames} frames of "
                f"{n_rotations} rotations ({rotation_bytes} bytes from block {start_block}) "
                f"but the file ends after {file_size} bytes")

    return C3DLayout(
        processor=PROCESSOR_NAMES[processor], parameter_block=parameter_block,
        n_points=n_points, n_analog_values=n_analog_values,
        analog_samples_per_frame=analog_samples_per_frame, first_frame=first_frame,
        n_frames=n_frames, is_float=is_float, data_start_block=data_start_block,
        rate=rate, file_size=file_size, parameters=parameters)


# --------------------------------------------------------------------------------------
# Reading and writing
# --------------------------------------------------------------------------------------

def _string_list(group: dict, key: str) -> list[str]:
    """A character parameter and its continuations (LABELS, LABELS2, LABELS3, …)."""
    values: list[str] = []
    for suffix in ("", *map(str, range(2, 100))):
        if key + suffix not in group:
            break
        value = group[key + suffix]["value"]
        values.extend([value] if isinstance(value, str) else list(value))
    return values


def read_c3d(path: str | os.PathLike) -> MarkerTrial:
    """Read the 3D points of a C3D file into a :class:`MarkerTrial` (SI units).

    The file is checked by :func:`inspect_c3d` before ezc3d reads it.  A sample is
    missing (NaN) when its residual is negative (C3D's "invalid point"), when a
    coordinate is not finite, or when all three coordinates are exactly zero (how many
    systems write gaps).  Units come from POINT:UNITS: mm, cm or m.

    Returns: MarkerTrial with ``positions (n_frames, n_markers, 3) m`` and
    ``time (n_frames,) s = (first_frame − 1 + k) / rate``.
    Raises: :class:`C3DError` naming the file.
    """
    name = os.fspath(path)
    layout = inspect_c3d(name)
    if not (layout.n_points or _first_number(layout.parameters, "POINT:USED")):
        raise C3DError(f"{name}: contains no 3D points (header and POINT:USED say 0)")
    try:
        c3d = ezc3d.c3d(name)
    except Exception as exc:  # ezc3d raises RuntimeError/IOError/ValueError by cause
        raise C3DError(f"{name}: ezc3d could not read the file: {exc}") from exc

    point_group = c3d["parameters"]["POINT"]
    points = np.asarray(c3d["data"]["points"], dtype=float)        # (4, n_markers, n_frames)
    residuals = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=float)
    n_markers = points.shape[1] if points.ndim == 3 else 0
    n_frames = points.shape[2] if points.ndim == 3 else 0
    if n_markers == 0 or n_frames == 0:
        raise C3DError(f"{name}: contains no marker data ({n_markers} points, "
                       f"{n_frames} frames)")

    labels = [lab.strip() for lab in _string_list(point_group, "LABELS")]
    if len(labels) < n_markers:
        raise C3DError(f"{name}: POINT:LABELS lists {len(labels)} labels for "
                       f"{n_markers} points")
    labels = labels[:n_markers]
    if _duplicates(labels):
        raise C3DError(f"{name}: duplicate marker labels {_duplicates(labels)}")

    units_values = _string_list(point_group, "UNITS")
    if not units_values:
        raise C3DError(f"{name}: POINT:UNITS is missing; expected one of mm, cm, m")
    units = units_values[0].strip()
    if units.lower() not in UNIT_TO_METRE:
        raise C3DError(f"{name}: POINT:UNITS is {units!r}; expected one of mm, cm, m")
    metres_per_unit = UNIT_TO_METRE[units.lower()]

    rate = float(np.asarray(point_group["RATE"]["value"], dtype=float).reshape(-1)[0])
    if not (np.isfinite(rate) and rate > 0):
        raise C3DError(f"{name}: POINT:RATE is {rate}, expected a positive rate in Hz")

    # p (n_frames, n_markers, 3) in file units; missing: residual < 0, non-finite, or 0,0,0
    p = np.transpose(points[:3], (2, 1, 0))
    residual = residuals[0].T if residuals.size else np.zeros(p.shape[:2])
    missing = ((residual < 0) | ~np.all(np.isfinite(p), axis=2) | np.all(p == 0.0, axis=2))
    positions = np.where(missing[:, :, None], np.nan, p * metres_per_unit)

    first_frame = max(layout.first_frame, 1)                        # 1-based
    time = (first_frame - 1 + np.arange(n_frames)) / rate
    return MarkerTrial(labels=tuple(labels), rate=rate, time=time, positions=positions,
                       source=name)


#: largest marker coordinate write_c3d accepts (m): a lab is smaller, mm data is not
MAX_LAB_COORDINATE_M = 100.0


def write_c3d(path: str | os.PathLike, labels: Sequence[str], positions: np.ndarray,
              rate: float, units: str = "mm") -> None:
    """Write marker positions to a float-format C3D file (with ezc3d).

    Args:
        path: file to write (replaced atomically if it exists).
        labels: n_markers unique, non-empty marker names.
        positions: ``(n_frames, n_markers, 3)`` in **metres** (SI, as every openfdk
            array), whatever ``units`` says: divide millimetre data by 1000 first. A
            sample with any NaN coordinate is written as missing (coordinates 0,
            residual −1). Coordinates beyond 100 m are refused as probably millimetres.
        rate: sample rate, Hz.
        units: unit of the numbers stored in the file and written to POINT:UNITS (mm,
            cm, m); the positions are converted from metres to it.

    Example: ``write_c3d("trial.c3d", ["M1"], p_mm / 1000.0, 100.0)`` stores mm.
    """
    name = os.fspath(path)
    labels = [str(lab).strip() for lab in labels]
    positions = np.asarray(positions, dtype=float)
    if units not in UNIT_TO_METRE:
        raise C3DError(f"{name}: cannot write units {units!r}; use mm, cm or m")
    if positions.ndim != 3 or positions.shape[1:] != (len(labels), 3) or not len(positions):
        raise C3DError(f"{name}: positions must have shape (n_frames ≥ 1, {len(labels)}, 3) "
                       f"for {len(labels)} labels, got {positions.shape}")
    if not labels or any(not lab for lab in labels):
        raise C3DError(f"{name}: every marker needs a non-empty label, got {labels}")
    if _duplicates(labels):
        raise C3DError(f"{name}: duplicate marker labels {_duplicates(labels)}")
    if not (np.isfinite(rate) and rate > 0):
        raise C3DError(f"{name}: rate must be a positive number of Hz, got {rate}")

    missing = ~np.all(np.isfinite(positions), axis=2)               # (n_frames, n_markers)
    largest = float(np.max(np.abs(positions[~missing]))) if (~missing).any() else 0.0
    if largest > MAX_LAB_COORDINATE_M:
        raise C3DError(f"{name}: positions must be in metres; a coordinate of {largest:g} m (beyond "
                       f"{MAX_LAB_COORDINATE_M:g} m) looks like millimetres: divide by 1000")
    stored = np.where(missing[:, :, None], 0.0, positions / UNIT_TO_METRE[units])
    n_frames, n_markers, _ = positions.shape
    points = np.ones((4, n_markers, n_frames))
    points[:3] = np.transpose(stored, (2, 1, 0))
    residuals = np.where(missing.T, -1.0, 0.0)[None, :, :]

    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [float(rate)]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = labels
    c3d["parameters"]["POINT"]["UNITS"]["value"] = [units]
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"]["residuals"] = residuals
    # ezc3d appends ".c3d" to other names: write a sibling temporary file, then rename
    target = Path(name)
    temporary = target.with_name(f".{target.name}.{os.getpid()}.tmp.c3d")
    try:
        c3d.write(str(temporary))
        os.replace(temporary, target)
    except Exception as exc:
        raise C3DError(f"{name}: ezc3d could not write the file: {exc}") from exc
    finally:
        if temporary.exists():
            temporary.unlink()
