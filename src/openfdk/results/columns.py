"""The fast reader of a result folder: each table's columns parsed when first used.

A result folder holds ``kinematics.csv`` (body poses, marker residuals), ``forces.csv``
(muscle, ligament, spring, contact and FDK columns) and ``summary.json`` (checked as
:func:`openfdk.results.run.read_summary` checks it). A 60 s run's forces.csv has some 3
million cells, of which the viewer draws a fifth: :func:`read_run_tables` keeps the cells
as text and converts a column when it is first used. :class:`~.run.RunResults` reads the
same files into pandas DataFrames; both check them with the same rules
(:func:`~.run.check_time_and_status`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.results import read_rows
from .run import TEXT_COLUMNS, check_time_and_status, read_summary


class ResultsError(ValueError):
    """A result folder cannot be read; the message names the file and the entry
    (``openfdk.viewer.ViewError`` is this class)."""


@dataclass
class RunTables:
    """The tables of one run, read by :func:`read_run_tables`.

    directory : Path; summary : dict (summary.json);
    kinematics, forces : {column name: (nf,) float array or list of str} (columns as
        written by :mod:`openfdk.io.results`, :class:`TableColumns` converted when used);
    time : (nf,) s.
    """

    directory: Path
    summary: dict
    kinematics: dict
    forces: dict = field(default_factory=dict)
    #: (start, end) s of :meth:`window`, None for the whole run
    span: tuple = None

    @property
    def time(self):
        return self.kinematics["time"]

    def window(self, start=None, end=None):
        """The run's frames with start ≤ t ≤ end (s; None: the run's first or last), as
        RunTables whose ``span`` other tables of the folder are cut to. ResultsError when
        no frame lies within."""
        t = np.asarray(self.time, float)
        lo = -np.inf if start is None else float(start)
        hi = np.inf if end is None else float(end)
        if np.isnan(lo) or np.isnan(hi) or lo > hi:
            raise ResultsError(f"--start/--end: [{lo:g}, {hi:g}] s is not a time window")
        keep = _within(t, (lo, hi))
        if not keep.any():
            span = f"{t[0]:g}–{t[-1]:g} s" if len(t) else "no frame"
            raise ResultsError(f"{self.directory / 'kinematics.csv'}: no frame within [{lo:g}, {hi:g}] s "
                               f"(the run covers {span})")
        return RunTables(self.directory, self.summary, self.kinematics.rows(keep),
                         self.forces.rows(keep) if self.forces else self.forces, (lo, hi))

    @property
    def n_frames(self):
        return len(self.time)

    def within_span(self, t):
        """(k,) bool: which times ``t`` (k,) s lie in the run's :meth:`window` (all for the
        whole run)."""
        t = np.asarray(t, float)
        return np.ones(t.shape, bool) if self.span is None else _within(t, self.span)


def _within(t, span):
    """(k,) bool: start − 1 ns ≤ t ≤ end + 1 ns for ``span`` (start, end) s."""
    return (t >= span[0] - 1e-9) & (t <= span[1] + 1e-9)


class TableColumns(Mapping):
    """{name: column} of a result table whose columns are converted when first used: a
    (nf,) float array (an empty cell read as NaN), or a list of str for the text columns
    ('message', 'status', 'fdk_reason'). A 60 s run's forces.csv has some 3 million
    cells of which the viewer draws a fifth; parsing only those halves the build. Using
    a column that is not numeric raises ResultsError naming the file and the column."""

    def __init__(self, path, names, cells):
        self._path = path
        self._cells = dict(zip(names, cells))
        self._columns = {}

    def __getitem__(self, name):
        column = self._columns.get(name)
        if column is None:
            cells = self._cells[name]
            try:
                column = np.array([c or "nan" for c in cells], dtype=float)
            except ValueError:
                if name not in TEXT_COLUMNS:
                    raise ResultsError(f"{self._path}: column {name!r}: values must be numbers") from None
                column = list(cells)
            self._columns[name] = column
        return column

    def rows(self, keep):
        """The table with only the rows where ``keep`` (nf,) bool is True."""
        keep = np.asarray(keep, bool)
        return TableColumns(self._path, list(self._cells), [[c for c, k in zip(cells, keep) if k]
                                                           for cells in self._cells.values()])

    def __iter__(self):
        return iter(self._cells)

    def __len__(self):
        return len(self._cells)


def read_columns(path):
    """A CSV written by :func:`openfdk.io.results.write_table` as :class:`TableColumns`
    (columns converted when used). Raises ResultsError naming the file for an unreadable
    file, a first column other than 'time', a row of the wrong length, a time that is
    not a finite number or a ``converged`` flag other than 0 or 1; a column used later
    that is not numeric raises ResultsError then."""
    path = Path(path)
    try:
        rows = read_rows(path)
    except OSError as exc:
        raise ResultsError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not rows or not rows[0] or rows[0][0] != "time":
        raise ResultsError(f"{path}: not an openfdk table (the first column must be 'time')")
    names, body = rows[0], rows[1:]
    for k, r in enumerate(body):
        if len(r) != len(names):
            raise ResultsError(f"{path}: row {k + 2} has {len(r)} fields, the header {len(names)}")
    cols = TableColumns(path, names, list(zip(*body)) if body else [()] * len(names))
    try:
        time = cols["time"]
    except ResultsError:
        raise ResultsError(f"{path}: column 'time' is not numeric") from None
    try:
        check_time_and_status(path, time, cols["converged"] if "converged" in cols else None)
    except ValueError as exc:
        raise ResultsError(str(exc)) from None
    return cols


def read_run_tables(directory):
    """Read a result folder (kinematics.csv required; forces.csv optional)."""
    d = Path(directory)
    if not d.is_dir():
        raise ResultsError(f"result folder {str(d)!r} does not exist")
    kin_path = d / "kinematics.csv"
    if not kin_path.is_file():
        raise ResultsError(f"{kin_path}: missing; a result folder written by 'openfdk run' is needed")
    summary = {}
    if (d / "summary.json").is_file():
        try:
            summary = read_summary(d / "summary.json")  # the schema plot and export-opensim check
        except ValueError as exc:
            raise ResultsError(str(exc)) from None
    kin = read_columns(kin_path)
    forces = read_columns(d / "forces.csv") if (d / "forces.csv").is_file() else {}
    if forces and len(forces["time"]) != len(kin["time"]):
        raise ResultsError(f"{d / 'forces.csv'}: {len(forces['time'])} rows, kinematics.csv has {len(kin['time'])}")
    return RunTables(d, summary, kin, forces)
