"""Reading an ``openfdk run`` result folder for the viewer.

A result folder holds ``kinematics.csv`` (body poses, marker residuals), ``forces.csv``
(muscle, ligament, spring, contact and FDK columns) and ``summary.json`` whose
``input.model`` (and ``input.model_file``, absolute, since the viewer exists) names the
model file and ``input.trial`` the trial. The viewer rebuilds geometry by loading that
model file.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.results import read_rows
from ..runresults import TEXT_COLUMNS, check_time_and_status, read_summary


class ViewError(ValueError):
    """A result folder cannot be viewed; the message names the file and the entry."""


@dataclass
class RunResults:
    """The tables of one run.

    directory : Path; summary : dict (summary.json);
    kinematics, forces : {column name: (nf,) float array or list of str} (columns as
        written by :mod:`openfdk.io.results`, :class:`TableColumns` converted when used);
    time : (nf,) s.
    """

    directory: Path
    summary: dict
    kinematics: dict
    forces: dict = field(default_factory=dict)

    @property
    def time(self):
        return self.kinematics["time"]

    @property
    def n_frames(self):
        return len(self.time)


class TableColumns(Mapping):
    """{name: column} of a result table whose columns are converted when first used: a
    (nf,) float array (an empty cell read as NaN), or a list of str for the text columns
    ('message', 'status', 'fdk_reason'). A 60 s run's forces.csv has some 3 million
    cells of which the viewer draws a fifth; parsing only those halves the build. Using
    a column that is not numeric raises ViewError naming the file and the column."""

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
                    raise ViewError(f"{self._path}: column {name!r}: values must be numbers") from None
                column = list(cells)
            self._columns[name] = column
        return column

    def __iter__(self):
        return iter(self._cells)

    def __len__(self):
        return len(self._cells)


def read_table(path):
    """A CSV written by :func:`openfdk.io.results.write_table` as :class:`TableColumns`
    (columns converted when used). Raises ViewError naming the file for an unreadable
    file, a first column other than 'time', a row of the wrong length, a time that is
    not a finite number or a ``converged`` flag other than 0 or 1; a column used later
    that is not numeric raises ViewError then."""
    path = Path(path)
    try:
        rows = read_rows(path)
    except OSError as exc:
        raise ViewError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not rows or not rows[0] or rows[0][0] != "time":
        raise ViewError(f"{path}: not an openfdk table (the first column must be 'time')")
    names, body = rows[0], rows[1:]
    for k, r in enumerate(body):
        if len(r) != len(names):
            raise ViewError(f"{path}: row {k + 2} has {len(r)} fields, the header {len(names)}")
    cols = TableColumns(path, names, list(zip(*body)) if body else [()] * len(names))
    try:
        time = cols["time"]
    except ViewError:
        raise ViewError(f"{path}: column 'time' is not numeric") from None
    try:
        check_time_and_status(path, time, cols["converged"] if "converged" in cols else None)
    except ValueError as exc:
        raise ViewError(str(exc)) from None
    return cols


def read_results(directory):
    """Read a result folder (kinematics.csv required; forces.csv optional)."""
    d = Path(directory)
    if not d.is_dir():
        raise ViewError(f"result folder {str(d)!r} does not exist")
    kin_path = d / "kinematics.csv"
    if not kin_path.is_file():
        raise ViewError(f"{kin_path}: missing; a result folder written by 'openfdk run' is needed")
    summary = {}
    if (d / "summary.json").is_file():
        try:
            summary = read_summary(d / "summary.json")  # the schema plot and export-opensim check
        except ValueError as exc:
            raise ViewError(str(exc)) from None
    kin = read_table(kin_path)
    forces = read_table(d / "forces.csv") if (d / "forces.csv").is_file() else {}
    if forces and len(forces["time"]) != len(kin["time"]):
        raise ViewError(f"{d / 'forces.csv'}: {len(forces['time'])} rows, kinematics.csv has {len(kin['time'])}")
    return RunResults(d, summary, kin, forces)


def _candidates(text, directory):
    p = Path(text)
    if p.is_absolute():
        yield p
        return
    yield Path.cwd() / p
    for parent in [directory, *directory.resolve().parents]:
        yield parent / p


def resolve_input(results, key, override=None):
    """Path of the run's ``key`` input ("model" or "trial"): ``override`` if given, else
    ``summary.json`` input.<key>_file (absolute) or input.<key> (as typed when the run
    was started: tried relative to the working directory, then to the result folder and
    its parents). Returns None when the summary names none; raises ViewError naming
    summary.json when it names a file that cannot be found."""
    if override is not None:
        p = Path(override)
        if not p.is_file():
            raise ViewError(f"{key} file {str(p)!r} does not exist")
        return p
    info = results.summary.get("input", {}) if isinstance(results.summary, dict) else {}
    for entry in (f"{key}_file", key):
        text = info.get(entry)
        if not isinstance(text, str) or not text:
            continue
        for p in _candidates(text, results.directory):
            if p.is_file():
                return p
    text = info.get(f"{key}_file") or info.get(key)
    if text:
        raise ViewError(f"{results.directory / 'summary.json'}: input.{key}: file {text!r} not found "
                        f"(give it with --{key})")
    return None
