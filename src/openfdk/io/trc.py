"""TRC marker files (Motion Analysis "Track Row Column", as read and written by OpenSim).

Layout (OpenSim documentation, "Marker (.trc) Files"), tab separated:

* line 1: ``PathFileType  4  (X/Y/Z)  <file name>``;
* line 2: names of the header fields, e.g. ``DataRate CameraRate NumFrames NumMarkers
  Units OrigDataRate OrigDataStartFrame OrigNumFrames``;
* line 3: their values, in the same order;
* line 4: ``Frame#  Time  <marker 1>  ''  ''  <marker 2> …`` (a marker's name sits over
  its x column, followed by two empty cells; names listed in order otherwise, with
  fewer or no empty cells between them, are read when there are NumMarkers of them, as
  OpenSim reads them);
* line 5: ``''  ''  X1  Y1  Z1  X2 …``;
* an optional blank line, then one row per frame: frame number, time (s), then x y z of
  every marker.  A missing sample is an empty cell or not-a-number in any spelling C
  runtimes print (``NaN``, ``-nan(ind)``, ``1.#QNAN``: :mod:`openfdk.io.numbers`), or
  infinite.  A sample whose three coordinates are all
  exactly zero is missing too: many exporters write gaps so (as C3D readers do, see
  :func:`openfdk.io.c3d.read_c3d`), and no real marker sits exactly on the lab origin.

Rows shorter than the header's 2 + 3·NumMarkers cells: a row may stop after a marker's
z (and a separator after it), which leaves its last markers missing (writers that drop
trailing empty cells), and is read so. When the last row alone is short, every other
row complete, the file was most likely cut short, and one warning names that line (a
writer that drops empty cells leaves short rows wherever its last markers are missing,
and is read without a warning). A row that stops inside a marker's x y z is refused
naming the line and the marker: no writer leaves a marker incomplete, so the row was cut
(a file copied in part, a line cut mid-number).

A coordinate farther than :data:`MAX_MARKER_DISTANCE` (1 km, after the unit conversion)
from the lab origin is refused naming the line, the time and the marker: no capture
volume is that large, so the number is corrupt or ``Units`` is wrong (mm written under
``m`` put a 2 m walkway 2 km away); such numbers overflow the checks and fits that
follow (an RMS residual of ``inf mm``).

A ``NumFrames`` other than the number of data rows is a warning, and the rows are read.
What is used: ``DataRate`` (Hz) is the trial's rate, ``Units`` (mm, cm or m) converts the
positions to metres once, here (docs/design.md §4); times are the ``Time`` column (which OpenSim
defines as (frame − OrigDataStartFrame)/DataRate).  The header fields are found by name,
not position.  Every problem raises :class:`TRCError` naming the file and the line.
"""

from __future__ import annotations

import math
import os
import stat
from decimal import Decimal, InvalidOperation

import numpy as np

from .c3d import UNIT_TO_METRE, MarkerTrial
from .numbers import parse_number

__all__ = ["TRCError", "read_trc"]

#: the largest distance (m) of a marker coordinate from the lab origin: no motion-capture
#: volume or walkway reaches 1 km; beyond it a number is corrupt (or Units is wrong)
MAX_MARKER_DISTANCE = 1e3
#: how many lines a warning names before it counts the rest
LISTED_LINES = 3

#: spellings of the Units field accepted besides mm / cm / m
UNIT_ALIASES = {"millimeters": "mm", "millimetres": "mm", "centimeters": "cm", "centimetres": "cm",
                "meters": "m", "metres": "m"}


class TRCError(ValueError):
    """A TRC file cannot be read; the message names the file, the line and the cause."""


def _cells(line: str) -> list[str]:
    """Split a line on tabs (the format's separator), or on whitespace if it has none."""
    line = line.rstrip("\r\n")
    return [c.strip() for c in line.split("\t")] if "\t" in line else line.split()


def _number(cell: str, name: str, line_no: int, what: str) -> float:
    """A cell's value (:func:`openfdk.io.numbers.parse_number`: NaN for every spelling of
    not-a-number C runtimes print, e.g. ``-nan(ind)``)."""
    try:
        return parse_number(cell)
    except ValueError:
        raise TRCError(f"{name}: line {line_no}: {what} is {cell!r}, expected a number") from None


def _count(cell: str, name: str, line_no: int, what: str) -> int:
    """A header count: a finite whole number >= 0 (NaN or inf would not convert)."""
    v = _number(cell, name, line_no, what)
    if not (math.isfinite(v) and v >= 0 and v == int(v)):
        raise TRCError(f"{name}: line {line_no}: {what} is {cell!r}, expected a whole number >= 0")
    return int(v)


def header_fields(path: str | os.PathLike) -> dict:
    """The header fields of a TRC file, {name on line 2: value on line 3} (str), reading
    its first three lines only. Raises OSError when the file cannot be read (or is not a
    regular file: a FIFO would block)."""
    if not stat.S_ISREG(os.stat(os.fspath(path)).st_mode):
        raise OSError(f"{os.fspath(path)}: not a regular file")
    with open(os.fspath(path), encoding="utf-8", errors="replace") as fh:
        head = [next(fh, "") for _ in range(3)]
    return _header(head[1], head[2])[1]


def _header(names_line, values_line):
    """(the field names, {name: value}) of header lines 2 and 3. Where the two lines
    have different numbers of cells, empty cells are dropped from both, as OpenSim's
    tokenizer drops them (opensim-models' Rajagopal walk puts two tabs between values)."""
    names, values = _cells(names_line), _cells(values_line)
    if len(values) != len(names):
        names, values = [c for c in names if c], [c for c in values if c]
    return names, dict(zip(names, values))


#: the offsets' resolution in :func:`_uniform_times` (s): far below any sample interval,
#: far above a double's round-off in a time of hours
NANOSECOND = Decimal("1e-9")


def _uniform_times(times, rate, cells):
    """The Time column on the exact grid t_0 + k/rate when it is that grid to the precision
    the file prints, else as read. times (n,) s; rate Hz; cells: the Time column's text.

    The precision is that of the offsets t_k − t_0, in decimal arithmetic on the printed
    text: OpenSim's example files print 60 Hz times rounded to 1 ms (offsets 0.017, 0.033),
    and the Knee Grand Challenge's treadmill TRCs print ms-rounded frame times plus a sync
    offset (0.439997, 0.447997, 0.456997: 8 and 9 ms steps of a 120 Hz camera, offsets
    to 1 ms; 140 of their 1 962 cells are printed with a double's round-off digits,
    0.5319970000000001, which the offsets' rounding to 1 ns drops). The column is the grid
    when every offset is within one unit of its last printed decimal of k/rate (two
    roundings: of t_k and of t_0), and within less than half a sample of it."""
    if len(times) < 2 or not rate > 0:
        return times
    try:
        first = Decimal(cells[0])
        decimals = max(-min((Decimal(c) - first).quantize(NANOSECOND).normalize().as_tuple().exponent, 0)
                       for c in cells[1:])
    except (InvalidOperation, ValueError, TypeError):
        return times
    grid = times[0] + np.arange(len(times)) / rate
    # never half a sample or more: a time that far off may be another frame (a dropped one)
    if np.max(np.abs(times - grid)) <= min(10.0 ** (-decimals) * (1 + 1e-9) + 1e-12, 0.499 / rate):
        return grid
    return times


def read_trc(path: str | os.PathLike) -> MarkerTrial:
    """Read a TRC file into a :class:`~openfdk.io.c3d.MarkerTrial` (SI units).

    Returns: MarkerTrial with ``positions (n_frames, n_markers, 3) m`` (NaN where a sample
    is missing), ``time (n_frames,) s`` from the Time column and ``rate`` = DataRate Hz.
    Raises: :class:`TRCError` naming the file and the line.
    """
    name = os.fspath(path)
    try:
        if not stat.S_ISREG(os.stat(name).st_mode):  # a FIFO or a device would block or never end
            raise TRCError(f"{name}: cannot read the file: not a regular file")
        with open(name, encoding="utf-8", errors="replace") as fh:
            lines = fh.readlines()
    except OSError as exc:
        raise TRCError(f"{name}: cannot read the file: {exc.strerror or exc}") from None
    from .placeholders import placeholder

    if (why := placeholder("".join(lines[:3]).encode())) is not None:
        raise TRCError(f"{name}: {why}")
    if len(lines) < 5:
        raise TRCError(f"{name}: a TRC file has at least 5 header lines, this one has {len(lines)} lines")
    if not lines[0].startswith("PathFileType"):
        raise TRCError(f"{name}: line 1 must start with 'PathFileType' (is this a TRC file?)")

    keys, header = _header(lines[1], lines[2])
    for key in ("DataRate", "NumMarkers", "Units"):
        if key not in header or header[key] == "":
            raise TRCError(f"{name}: line 2/3: header field {key!r} is missing (fields: {keys})")
    rate = _number(header["DataRate"], name, 3, "DataRate")
    if not (math.isfinite(rate) and rate > 0):
        raise TRCError(f"{name}: line 3: DataRate is {rate}, expected a positive rate in Hz")
    n_declared = _count(header["NumMarkers"], name, 3, "NumMarkers")
    units = UNIT_ALIASES.get(header["Units"].lower(), header["Units"].lower())
    if units not in UNIT_TO_METRE:
        raise TRCError(f"{name}: line 3: Units is {header['Units']!r}; expected one of mm, cm, m")

    label_cells = _cells(lines[3])
    if len(label_cells) < 2 or label_cells[0] != "Frame#" or label_cells[1] != "Time":
        raise TRCError(f"{name}: line 4 must start with 'Frame#' and 'Time', got {label_cells[:2]}")
    if "\t" in lines[3]:
        # a name over the x column of each marker: columns 2, 5, 8, ...
        labels = [label_cells[c] for c in range(2, len(label_cells), 3)]
    else:
        labels = label_cells[2:]
    while labels and labels[-1] == "":
        labels.pop()
    listed = [c for c in label_cells[2:] if c]
    if ("" in labels or len(labels) != int(n_declared)) and len(listed) == int(n_declared):
        # the names in order, not over their x columns (OpenSim's Matlab utilities put one
        # empty cell between names; an IMU export none): as OpenSim reads them
        labels = listed
    if "" in labels:
        raise TRCError(f"{name}: line 4: marker {labels.index('') + 1} has no name")
    if len(labels) != int(n_declared):
        raise TRCError(f"{name}: line 4 names {len(labels)} markers, NumMarkers on line 3 says {int(n_declared)}")
    if len(set(labels)) != len(labels):
        dup = sorted({lab for lab in labels if labels.count(lab) > 1})
        raise TRCError(f"{name}: line 4: duplicate marker labels {dup}")

    n_markers = len(labels)
    n_values = 2 + 3 * n_markers
    times, rows, time_cells, row_lines, short = [], [], [], [], []
    for line_no, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = _cells(line)
        if len(cells) > n_values and any(c for c in cells[n_values:]):
            raise TRCError(f"{name}: line {line_no}: {len(cells)} values, expected at most {n_values} "
                           f"(frame, time and x y z of {n_markers} markers)")
        if len(cells) < n_values:
            given = len(cells)
            while given > 2 and (given - 2) % 3 and cells[given - 1] == "":
                given -= 1          # a separator after the last value (writers that end every cell with a tab)
            if given > 2 and (given - 2) % 3:
                m = (given - 2) // 3
                raise TRCError(f"{name}: line {line_no}: the row stops inside marker {labels[m]!r} "
                               f"({(given - 2) % 3} of its x y z): {len(cells)} values, expected {n_values} "
                               f"(frame, time and x y z of {n_markers} markers); a row cut short?")
            short.append(line_no)
        cells = cells + [""] * (n_values - len(cells))
        times.append(_number(cells[1], name, line_no, "the time"))
        if not math.isfinite(times[-1]):
            raise TRCError(f"{name}: line {line_no}: the time is {cells[1]!r}, expected a finite number")
        time_cells.append(cells[1])
        row = np.full(3 * n_markers, np.nan)
        for j, cell in enumerate(cells[2:n_values]):
            if cell != "":
                row[j] = _number(cell, name, line_no, f"column {j + 3}")
        rows.append(row)
        row_lines.append(line_no)
    if not rows:
        raise TRCError(f"{name}: contains no data rows")
    if short == row_lines[-1:]:
        # only the last row is short: a file cut short (copied in part, a writer stopped)
        # ends so; a writer that drops trailing empty cells leaves short rows wherever the
        # last markers are missing, and is read without a word
        import warnings

        warnings.warn(f"{name}: line {short[0]}, the last row, stops before the last marker ({n_values} values "
                      f"expected: frame, time and x y z of {n_markers} markers) where every other row is complete: "
                      "its last markers are read as missing; was the file cut short?")
    if "NumFrames" in header and header["NumFrames"] != "":
        declared = _count(header["NumFrames"], name, 3, "NumFrames")
        if declared != len(rows):
            # OpenSim's own example trials were cut short without their header (walk_free_01:
            # 900 declared, 73 rows): read as OpenSim reads them, and say so
            import warnings

            warnings.warn(f"{name}: NumFrames on line 3 is {declared}, the file has {len(rows)} data "
                          f"rows; the {len(rows)} rows are read")

    times = _uniform_times(np.array(times), rate, time_cells)
    p = np.array(rows).reshape(len(rows), n_markers, 3) * UNIT_TO_METRE[units]
    far = np.isfinite(p) & (np.abs(p) > MAX_MARKER_DISTANCE)
    if far.any():
        k, m, axis = (int(i) for i in np.argwhere(far)[0])
        raise TRCError(f"{name}: line {row_lines[k]}: marker {labels[m]!r} at time {times[k]:g} s: "
                       f"{'xyz'[axis]} = {rows[k][3 * m + axis]:g} {units} is beyond {MAX_MARKER_DISTANCE:g} m from "
                       f"the origin, farther than any capture volume (a corrupt number, or the wrong Units on line 3?)")
    # a sample is missing when any coordinate is: the marker is seen or not as a whole;
    # (0, 0, 0) exactly is how many exporters write a gap
    p[~np.all(np.isfinite(p), axis=2) | np.all(p == 0.0, axis=2)] = np.nan
    try:
        return MarkerTrial(labels=tuple(labels), rate=rate, time=times, positions=p, source=name)
    except ValueError as exc:
        raise TRCError(str(exc)) from None
