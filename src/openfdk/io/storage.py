"""OpenSim storage files: ``.sto`` (any time series) and ``.mot`` (coordinates).

Layout (OpenSim documentation, "Storage (.sto) Files" and "Motion (.mot) Files"; the
header of OpenSim ≥ 2.3.2 adds ``version`` and ``inDegrees``)::

    <name>                  the name OpenSim shows for the data
    version=1
    nRows=<data rows>
    nColumns=<columns, time included>
    inDegrees=<yes|no>      whether angular columns are in degrees
    <optional comment lines>
    endheader
    time<TAB>label 1<TAB>…  column labels
    0<TAB>…                 one tab-separated row per time, time first

Values are written with Python's shortest round-trip representation (``repr``), so a
reader gets back exactly the float that was written; a missing value is ``NaN``.
Column labels must not contain tabs or line breaks.  Text columns (e.g. ``message``)
cannot be stored: :func:`csv_to_sto` drops them and says so in a comment line.
"""

from __future__ import annotations

import csv
import math
import os
import stat
import warnings
from pathlib import Path

import numpy as np

from .numbers import NUMBER, value_of_number

__all__ = ["write_storage", "csv_to_sto"]


def _format(x: float) -> str:
    x = float(x)
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "Inf" if x > 0 else "-Inf"
    return repr(x)


def write_storage(path, time, columns: dict, name: str = "openfdk", in_degrees: bool = False,
                  comments=()) -> Path:
    """Write an OpenSim ``.sto``/``.mot`` file (atomically: temporary file + rename).

    Args:
        path: file to write.
        time: ``(n_rows,) s`` sample times.
        columns: label -> ``(n_rows,)`` numbers, in column order (``time`` excluded).
        name: first header line.
        in_degrees: value of the ``inDegrees`` header field (the angular columns' unit).
        comments: extra header lines (no ``endheader`` among them).
    Returns: the path written.
    """
    path = Path(path)
    time = np.asarray(time, dtype=float).reshape(-1)
    labels = list(columns)
    data = [np.asarray(columns[k], dtype=float).reshape(-1) for k in labels]
    for label, col in zip(labels, data):
        if col.shape != time.shape:
            raise ValueError(f"{path}: column {label!r} has {col.size} rows, time has {time.size}")
        if not label or any(c in label for c in "\t\r\n"):
            raise ValueError(f"{path}: column label {label!r} is empty or has a tab or line break")
    for line in [name, *comments]:
        if "\n" in line or line.strip() == "endheader":
            raise ValueError(f"{path}: header line {line!r} is not allowed")
    header = [name, "version=1", f"nRows={time.size}", f"nColumns={len(labels) + 1}",
              f"inDegrees={'yes' if in_degrees else 'no'}", *comments, "endheader",
              "\t".join(["time", *labels])]
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with open(tmp, "w", newline="\n") as fh:
        fh.write("\n".join(header) + "\n")
        table = np.column_stack([time, *data]) if data else time[:, None]
        for row in table:
            fh.write("\t".join(_format(x) for x in row) + "\n")
    os.replace(tmp, path)
    return path



def write_converged_storage(path, time, columns: dict, ok, name: str) -> Path:
    """:func:`write_storage` of the rows ``ok`` (nf,) bool of a run's table (time (nf,) s,
    columns label -> (nf,)): failed frames are left out of the ``.sto``, which says how
    many in its header (the CSV twin keeps them, NaN)."""
    ok = np.asarray(ok, bool)
    return write_storage(path, np.asarray(time, float)[ok], {k: np.asarray(v)[ok] for k, v in columns.items()},
                         name=name, comments=[] if ok.all() else [f"openfdk: {int((~ok).sum())} failed frames left out"])

def write_run_table(out_dir, stem, time, columns: dict, name: str, ok=None, sto_columns=None):
    """``stem``.csv with every frame of a run's table (time (nf,) s, columns label ->
    (nf,)) and its ``.sto`` twin with the frames ``ok`` (nf,) bool (default: those whose
    columns are all finite; :func:`write_converged_storage`), of ``sto_columns``
    (default: all of them)."""
    from .results import write_table

    out_dir, time = Path(out_dir), np.asarray(time, float)
    write_table(out_dir / f"{stem}.csv", {"time": time, **columns})
    if ok is None:
        ok = np.isfinite(np.column_stack(list(columns.values()))).all(axis=1)
    write_converged_storage(out_dir / f"{stem}.sto", time, columns if sto_columns is None else sto_columns, ok, name)


def csv_to_sto(csv_path, sto_path=None, name=None) -> Path | None:
    """Convert an openfdk result table (``kinematics.csv``, ``forces.csv``: first column
    ``time``, SI units) to ``.sto`` beside it (or at ``sto_path``).  Numeric columns are
    kept in order; text columns (``message``, ``status``, ``fdk_reason``) are dropped and
    listed in a header comment.  Angular columns are in rad (``inDegrees=no``).
    Returns the path written, or None when the table has no rows."""
    csv_path = Path(csv_path)
    sto_path = Path(sto_path) if sto_path else csv_path.with_suffix(".sto")
    with open(csv_path, newline="") as fh:
        rows = list(csv.reader(fh))
    if len(rows) < 2:
        return None
    header, body = rows[0], rows[1:]
    if header[0] != "time":
        raise ValueError(f"{csv_path}: the first column must be 'time', got {header[0]!r}")
    numeric, dropped = {}, []
    for j, label in enumerate(header[1:], start=1):
        try:
            numeric[label] = [float(r[j]) for r in body]
        except ValueError:
            dropped.append(label)
    time = [float(r[0]) for r in body]
    comments = [f"Source: {csv_path.name} (openfdk); SI units (m, s, N, rad), see docs/outputs.md"]
    if dropped:
        comments.append(f"Text columns not stored: {', '.join(dropped)}")
    return write_storage(sto_path, time, numeric, name=name or csv_path.stem, comments=comments)


class StorageColumns(dict):
    """{label: (n,) values} of a storage file (:func:`read_storage`); ``twice``: the
    labels given twice with different values, left out; ``header``: {field name in lower
    case: (line number, value as written)} of the header's ``key=value`` lines
    (``nrows``, ``ncolumns``, ``indegrees``, …); ``labels``: {key: the file's label}
    where a reader keys the columns otherwise (:func:`openfdk.io.opensim.motion.by_coordinate`);
    ``n_labels``: the number of labels on the file's label line, time included."""

    twice: frozenset = frozenset()
    header: dict = {}
    labels: dict = {}
    n_labels: int = 0

    def label(self, key) -> str:
        """The file's label of the column ``key``."""
        return self.labels.get(key, key)

    def absent(self, label) -> str:
        """Why ``label`` is not a column, for a message: "no column 'x'" or "column 'x' is
        given twice with different values"."""
        if label in self.twice:
            return f"column {label!r} is given twice with different values"
        return f"no column {label!r}"


def read_storage(path, warn_counts=False):
    """Read an OpenSim ``.sto``/``.mot`` file: (time (n,) s, StorageColumns {label: (n,)
    values}, in_degrees bool). Values are as in the file (angles in degrees when ``inDegrees=yes``).
    Errors are one line naming the file and the line. With ``warn_counts``, a header's
    ``nRows``/``nColumns`` other than the data's rows/columns (time included) is one
    warning naming the file and the line (:func:`count_mismatch`), and the data are read
    as they are (OpenSim's own tutorial files disagree so: crouch2.mot declares 120 rows
    and has 101, Moco's example3DWalking coordinates.sto 40 columns and has 32)."""
    path = Path(path)
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):  # a FIFO or a device would block or never end
            raise ValueError(f"{path.name}: cannot read the file (not a regular file)")
        lines = path.read_text(errors="replace").splitlines()
    except OSError as exc:
        raise ValueError(f"{path.name}: cannot read the file ({exc.strerror or exc})") from None
    from .placeholders import placeholder

    if (why := placeholder("\n".join(lines[:3]).encode())) is not None:
        raise ValueError(f"{path.name}: {why}")
    try:
        end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    except StopIteration:
        raise ValueError(f"{path.name}: no 'endheader' line: not an OpenSim storage file") from None
    in_degrees = False
    header = {}
    for k, line in enumerate(lines[:end], start=1):
        key, sep, value = "".join(line.split()).lower().partition("=")
        if sep and key not in header:
            header[key] = (k, value)
        if key == "indegrees":
            if value not in ("yes", "no"):
                raise ValueError(f"{path.name}: line {k}: inDegrees must be yes or no, got {line.strip()[:40]!r}")
            in_degrees = value == "yes"
    while end + 1 < len(lines) and not lines[end + 1].strip():   # blank lines (OpenSim skips them)
        end += 1
    if end + 1 >= len(lines):
        raise ValueError(f"{path.name}: no column labels after 'endheader'")
    labels = lines[end + 1].split("\t") if "\t" in lines[end + 1] else lines[end + 1].split()
    # empty cells are dropped, as from the data rows (split on white space) and by OpenSim's
    # tokenizer: trailing tabs (OpenSim's example GRF files), a double tab between labels
    # (its SinglePin_InitialStates.sto)
    labels = [x.strip() for x in labels if x.strip()]
    if not labels or labels[0].lower() != "time":
        raise ValueError(f"{path.name}: line {end + 2}: the first column must be 'time', got {labels[:1]}")
    rows = []
    for k, line in enumerate(lines[end + 2:], start=end + 3):
        if not line.strip():
            continue
        cells = line.split()
        if len(cells) != len(labels):
            raise ValueError(f"{path.name}: line {k}: {len(cells)} values for {len(labels)} columns")
        if not all(NUMBER.match(c) for c in cells):
            # a decimal number, or NaN / Inf in any spelling C runtimes print (OpenSim's
            # files written on Windows: '-nan(ind)'); not '1_000', hexadecimal or
            # non-ASCII digits, which Python's float reads
            j = next(j for j, c in enumerate(cells) if not NUMBER.match(c))
            raise ValueError(f"{path.name}: line {k}: column {labels[j]!r} is {cells[j][:40]!r}, expected a number")
        rows.append([value_of_number(c) for c in cells])
    data = np.array(rows, dtype=float).reshape(-1, len(labels))
    if not np.all(np.isfinite(data[:, 0])) or np.any(np.diff(data[:, 0]) <= 0):
        raise ValueError(f"{path.name}: the times are not finite and increasing")
    if labels[0] in labels[1:]:
        raise ValueError(f"{path.name}: line {end + 2}: column {labels[0]!r} is given twice")
    columns = {}
    for j, label in enumerate(labels[1:], start=1):
        if label in columns and not np.array_equal(columns[label], data[:, j], equal_nan=True):
            columns[label] = None          # given twice with different values: ambiguous
        elif label not in columns:
            columns[label] = data[:, j]
    twice = [label for label, values in columns.items() if values is None]
    if twice:
        # the IK .mot files of OpenSim's gait tutorials carry both plates' ground_force_*
        # under the same labels: the coordinates are read, those columns are not
        warnings.warn(f"{path.name}: line {end + 2}: columns {twice} are given twice with different "
                      f"values; they are not read")
    if warn_counts and (note := count_mismatch(path.name, header, len(rows), len(labels))):
        warnings.warn(note, stacklevel=2)
    out = StorageColumns((label, v) for label, v in columns.items() if v is not None)
    out.twice = frozenset(twice)
    out.header = header
    out.n_labels = len(labels)
    return data[:, 0], out, in_degrees


def count_mismatch(name, header, n_rows, n_columns):
    """The warning (one line) when the header's ``nRows``/``nColumns`` (``header``: {key:
    (line, value)}, :attr:`StorageColumns.header`) contradict the ``n_rows`` data rows
    and ``n_columns`` labels (time included, :attr:`StorageColumns.n_labels`) of the
    file ``name``; None when they agree or are not given."""
    found = []
    for key, spelt, actual, what in (("nrows", "nRows", n_rows, "data rows"),
                                      ("ncolumns", "nColumns", n_columns, "columns (time included)")):
        if key not in header:
            continue
        line, value = header[key]
        try:
            declared = int(value)
        except ValueError:
            declared = None
        if declared != actual:
            found.append(f"line {line}: {spelt}={value[:20]}, the file has {actual} {what}")
    return f"{name}: {'; '.join(found)}; the data are read as they are" if found else None


#: the highest sampling rate a run takes (the model file's bound on analysis.rate_hz, Hz)
MAX_RATE_HZ = 1e6
#: the largest |time| (s): 317 years, longer than any recording lasts; Unix time in
#: seconds (1.7e9) is below it, and then refused by TIME_RESOLUTION unless resolved
MAX_TIME = 1e10
#: the smallest spacing of two samples relative to the times' magnitude: the outputs
#: print times to 10 significant digits, so closer samples print (nearly) alike
TIME_RESOLUTION = 1e-9


def sample_times_problem(times, source, printed=True):
    """The one-line refusal of a storage file's times (n,) s (finite, increasing) that a
    run cannot resolve, or '': beyond MAX_TIME; less than 1/MAX_RATE_HZ s apart; with
    ``printed`` (times the results print: a motion file's are the frames'), less than
    TIME_RESOLUTION of the times' magnitude apart (an offset clock). ``source`` names the
    file. Used for motion files (:func:`openfdk.io.opensim.motion.check_times`) and
    ExternalLoads data (:mod:`openfdk.forces.data_load_section`, ``printed`` False: they
    are interpolated at the trial's frames), whose samples at 1e-300 s spacing gave NaN
    loads."""
    import numpy as np

    times = np.asarray(times, dtype=float)
    if len(times) == 0:
        return ""
    k = int(np.argmax(np.abs(times)))
    magnitude = abs(float(times[k]))
    if magnitude > MAX_TIME:
        return (f"{source}: time {float(times[k])!r} s (sample {k + 1}) is beyond {MAX_TIME:g} s (317 years), "
                "longer than any recording")
    if len(times) < 2:
        return ""
    gaps = np.diff(times)
    k = int(np.argmin(gaps))
    pair = f"times {float(times[k])!r} and {float(times[k + 1])!r} s are {gaps[k]:.3g} s apart"
    if gaps[k] < 1.0 / MAX_RATE_HZ:
        return (f"{source}: {pair}: a sampling rate above {MAX_RATE_HZ:g} Hz, the highest a run takes "
                "(analysis.rate_hz)")
    if printed and gaps[k] < TIME_RESOLUTION * magnitude:
        return (f"{source}: {pair}, less than {TIME_RESOLUTION:g} of their magnitude: the results print "
                "times to 10 significant digits, too few to tell the samples apart (a clock's offset, such "
                "as Unix time? subtract the start time)")
    return ""
