"""The results of one run as pandas tables: built in memory from an analysis, or read
back from a result folder (``kinematics.csv``, ``forces.csv``, ``summary.json``).

:class:`RunResults` is what :func:`openfdk.run` and :func:`openfdk.read_results` return
(docs/python-api.md); the figures (:mod:`openfdk.plots.run`) and the OpenSim export
(:mod:`openfdk.io.osim`) read it too.  Column meanings: docs/outputs.md.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["RunResults", "read_results", "read_summary", "conjugate_unit", "measure_unit"]

KINEMATICS_CSV, FORCES_CSV, MEASURES_CSV, SUMMARY_JSON = "kinematics.csv", "forces.csv", "measures.csv", "summary.json"
#: the joint coordinates of a model that has them (OpenSim's; io/coordinate_outputs.py)
COORDINATES_CSV = "coordinates.csv"
JOINT_LOADS_CSV = "joint_loads.csv"
MOMENT_ARMS_CSV = "moment_arms.csv"
#: per-frame text columns
TEXT_COLUMNS = ("message", "status", "fdk_reason")
_SI = {"length": "m", "angle": "rad", "1": "1"}
_CONJUGATE = {"length": "N", "angle": "N·m", "1": "N·m"}


#: the FDK solver's per-frame columns of forces.csv (RunResults.fdk)
FDK_FRAME_COLUMNS = ("fdk_converged", "fdk_iterations", "fdk_evaluations", "fdk_jacobians", "fdk_restarts",
                     "fdk_backward", "fdk_reason")
#: column-name unit suffixes of an FDK DOF of a measure kind, and of its residual force
_SUFFIX = {"length": "m", "angle": "rad", "1": "1"}
_CONJUGATE_SUFFIX = {"length": "N", "angle": "Nm", "1": "Nm"}


def measure_unit(kind: str) -> str:
    """SI unit of a measure component of kind "length" / "angle" / "1"."""
    return _SI.get(kind, kind)


def conjugate_unit(kind: str) -> str:
    """Unit of the generalized force conjugate to a measure component (work / measure):
    N for a length, N·m for an angle or a dimensionless measure (axis dot product)."""
    return _CONJUGATE.get(kind, "N or N·m")


def _frame(columns: dict):
    """DataFrame indexed by ``time`` (s) from a column dict (name -> (nf,) values)."""
    import pandas as pd

    df = pd.DataFrame({k: (list(v) if k in TEXT_COLUMNS else np.asarray(v)) for k, v in columns.items()})
    return df.set_index("time")


def _check_rows(path):
    """ValueError naming ``path`` and the line when a row has another number of fields
    than the header (a file cut mid-row, or not a table written by openfdk)."""
    import csv

    with open(path, newline="", encoding="utf-8", errors="replace") as fh:
        rows = csv.reader(fh)
        header = next(rows, None)
        if not header:
            raise ValueError(f"{path}: empty file; not an openfdk result table")
        for line, row in enumerate(rows, start=2):
            if len(row) != len(header):
                raise ValueError(f"{path}: line {line}: {len(row)} fields where the header has {len(header)} "
                                 f"(file cut short or not written by openfdk)")


def _read_csv(path, required=("time",)):
    import pandas as pd

    _check_rows(path)
    try:
        df = pd.read_csv(path, keep_default_na=False, na_values=["nan", "NaN"],
                         dtype={k: str for k in TEXT_COLUMNS})
    except (ValueError, pd.errors.ParserError) as exc:
        raise ValueError(f"{path}: not a readable table: {' '.join(str(exc).split())}") from None
    if df.columns[0] != "time":
        raise ValueError(f"{path}: the first column must be 'time', got {df.columns[0]!r}")
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise ValueError(f"{path}: column {missing[0]!r} missing; not a table written by openfdk")
    for c in df.columns:
        if c not in TEXT_COLUMNS and not pd.api.types.is_numeric_dtype(df[c]):
            raise ValueError(f"{path}: column {c!r}: values must be numbers")
    check_time_and_status(path, df["time"].to_numpy(), df["converged"].to_numpy() if "converged" in df.columns
                          else None)
    return df.set_index("time")


def check_time_and_status(path, time, converged=None):
    """ValueError naming the file, the column and the line (1-based, the header is line
    1) of a time (s) that is not a finite number or does not increase, or a ``converged``
    flag other than 0 or 1 (the readers of plot, export-opensim and view share it)."""
    time = np.asarray(time, dtype=float)
    if not np.all(np.isfinite(time)):
        i = int(np.argmax(~np.isfinite(time)))
        raise ValueError(f"{path}: line {i + 2}: column 'time': {time[i]:g} is not a finite number of seconds")
    if time.size > 1 and np.any(np.diff(time) <= 0.0):
        i = int(np.argmax(np.diff(time) <= 0.0)) + 1
        raise ValueError(f"{path}: line {i + 2}: column 'time': {time[i]:g} s does not follow {time[i - 1]:g} s "
                         "(times must increase)")
    if converged is not None:
        flags = np.asarray(converged, dtype=float)
        bad = (flags != 0) & (flags != 1)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"{path}: line {i + 2}: column 'converged': {flags[i]:g} is neither 0 nor 1")


def read_summary(path):
    """summary.json checked against its schema: an object whose ``input``,
    ``kinematics``, ``inverse_dynamics`` and ``fdk`` entries are objects (a JSON null is
    read as the entry left out) and whose input
    file names (``input.model``, ``model_file``, ``trial``, ``trial_file``) are text."""
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(summary, dict):
        raise ValueError(f"{path}: must be a JSON object, got {type(summary).__name__}")
    for key in ("input", "kinematics", "inverse_dynamics", "fdk"):
        if key in summary and summary[key] is None:  # JSON null: the section is absent
            del summary[key]
        if key in summary and not isinstance(summary[key], dict):
            raise ValueError(f"{path}: {key}: must be a JSON object, got {type(summary[key]).__name__}")
    for key in ("model", "model_file", "trial", "trial_file"):
        value = (summary.get("input") or {}).get(key)
        if value is not None and not isinstance(value, str):
            raise ValueError(f"{path}: input.{key}: must be a file name (text), got {json.dumps(value)}")
    return summary


#: the columns of a body's pose in kinematics.csv (position, m, and quaternion)
POSE_COLUMNS = ("x_m", "y_m", "z_m", "e0", "e1", "e2", "e3")


def _check_tables(d, kinematics, others):
    """ValueError naming the file when a body's pose in kinematics.csv is incomplete, or
    when another table (forces.csv, measures.csv) has other frames than kinematics.csv."""
    for c in kinematics.columns:
        if c.endswith(".x_m"):
            body = c[:-4]
            missing = [f"{body}.{p}" for p in POSE_COLUMNS if f"{body}.{p}" not in kinematics.columns]
            if missing:
                raise ValueError(f"{d / KINEMATICS_CSV}: column {missing[0]!r} missing; the pose of body {body!r} "
                                 f"is incomplete (not a table written by openfdk)")
    t = kinematics.index.to_numpy()
    for name, df in others.items():
        if df is None:
            continue
        u = df.index.to_numpy()
        if len(u) != len(t) or not np.array_equal(u, t):
            raise ValueError(f"{d / name}: {len(u)} frames whose times differ from the {len(t)} frames of "
                             f"{KINEMATICS_CSV} (file cut short or from another run)")


class RunResults:
    """One run: kinematics, forces, FDK and convergence, as pandas DataFrames.

    Attributes:
        kinematics: DataFrame indexed by time (s), the columns of kinematics.csv.
        forces: DataFrame indexed by time (s), the columns of forces.csv (None for a
            kinematics-only run).
        measures: DataFrame indexed by time (s), the model's named measures per frame
            (measures.csv: ``name_unit`` / ``name[k]_unit``, SI), None if it has none.
        coordinates: DataFrame indexed by time (s), the model's joint coordinates per
            frame (coordinates.csv: ``name_rad`` / ``name_m``, SI; NaN where the
            kinematics failed), None for a model without coordinates.
        joint_loads: DataFrame indexed by time (s), the load each joint transmits to its
            child body (joint_loads.csv, OpenSim's JointReaction columns
            ``{joint}_on_{child}_in_ground_fx`` … ``_pz``: N, N m, m;
            :mod:`openfdk.io.joint_load_outputs`), None for a model without coordinates
            or a kinematics-only run.
        moment_arms: DataFrame indexed by time (s), each muscle's moment arm about each
            coordinate it spans (moment_arms.csv, ``{muscle}.{coordinate}``: m per rad or
            m per m; ``openfdk run --moment-arms``, :mod:`openfdk.io.moment_arm_outputs`),
            None when not asked for.
        summary: dict, the content of summary.json.
        directory: the folder the run was saved to or read from (None if not saved).
    """

    def __init__(self, kinematics, forces, summary: dict, model=None, directory=None, measures=None,
                 coordinates=None, joint_loads=None, moment_arms=None):
        self.kinematics = kinematics
        self.forces = forces
        self.measures = measures
        self.coordinates = coordinates
        self.joint_loads = joint_loads
        self.moment_arms = moment_arms
        self.summary = summary
        self._model = model
        self.directory = None if directory is None else Path(directory)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_analysis(cls, kin, dyn, info: dict, model=None, reports=()):
        """From a KinematicsResult, an InverseDynamicsResult (or None) and the job info
        (as returned by :func:`openfdk.analysis.jobs.run_job`); ``reports``: the joint
        loads asked for besides the defaults (the settings' ``joint_reaction``)."""
        from ..io.results import forces_columns, kinematics_columns

        info = dict(info)
        fdk = info.pop("fdk", None)
        summary = {"input": info, "kinematics": kin.summary()}
        if dyn is not None:
            summary["inverse_dynamics"] = dyn.summary()
        if fdk is not None:
            summary["fdk"] = fdk
        forces = None if dyn is None else _frame(forces_columns(dyn))
        measures = None
        if model is not None and model.measures:
            from ..io.measure_outputs import measure_columns

            measures = _frame(measure_columns(model, kin))
        coordinates = joint_loads = None
        if model is not None and getattr(model, "coordinates", None):
            from ..io.coordinate_outputs import coordinate_columns

            coordinates = _frame(coordinate_columns(model, kin))
            if dyn is not None and len(dyn.time):
                from ..io.joint_load_outputs import joint_load_columns, joint_load_summary

                columns = joint_load_columns(model, kin, dyn, reports)
                if columns:
                    joint_loads = _frame({"time": np.asarray(dyn.time, float), **columns})
                    summary["joint_loads"] = joint_load_summary(model, dyn.time, columns)
        return cls(_frame(kinematics_columns(kin)), forces, summary, model, measures=measures,
                   coordinates=coordinates, joint_loads=joint_loads)

    @classmethod
    def read(cls, directory, model=None):
        """Read a result folder written by ``openfdk run``/``kinematics`` or :meth:`save`;
        ``model``: the analysed Model when the caller has it (else :meth:`model` loads it
        from the model file when asked)."""
        d = Path(directory)
        if not (d / KINEMATICS_CSV).is_file():
            raise FileNotFoundError(f"{d}: no {KINEMATICS_CSV}; is this an openfdk result folder?")
        summary = read_summary(d / SUMMARY_JSON) if (d / SUMMARY_JSON).is_file() else {}
        forces = _read_csv(d / FORCES_CSV, ("time", "converged")) if (d / FORCES_CSV).is_file() else None
        measures = _read_csv(d / MEASURES_CSV) if (d / MEASURES_CSV).is_file() else None
        coordinates = _read_csv(d / COORDINATES_CSV) if (d / COORDINATES_CSV).is_file() else None
        joint_loads = _read_csv(d / JOINT_LOADS_CSV) if (d / JOINT_LOADS_CSV).is_file() else None
        moment_arms = _read_csv(d / MOMENT_ARMS_CSV) if (d / MOMENT_ARMS_CSV).is_file() else None
        kinematics = _read_csv(d / KINEMATICS_CSV, ("time", "converged"))
        _check_tables(d, kinematics, {FORCES_CSV: forces, MEASURES_CSV: measures, COORDINATES_CSV: coordinates,
                                      JOINT_LOADS_CSV: joint_loads, MOMENT_ARMS_CSV: moment_arms})
        return cls(kinematics, forces, summary, model, d, measures, coordinates, joint_loads, moment_arms)

    def save(self, directory, sto: bool = True):
        """Write kinematics.csv, forces.csv, measures.csv, coordinates.csv,
        joint_loads.csv, moment_arms.csv, summary.json (and the ``.sto`` twins of the CSV files but
        coordinates.csv unless ``sto=False``) into ``directory`` (created). Returns the
        folder."""
        from ..io.results import write_json, write_table
        from ..io.storage import csv_to_sto

        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        for name, df in ((KINEMATICS_CSV, self.kinematics), (FORCES_CSV, self.forces),
                         (MEASURES_CSV, self.measures), (COORDINATES_CSV, self.coordinates),
                         (JOINT_LOADS_CSV, self.joint_loads), (MOMENT_ARMS_CSV, self.moment_arms)):
            if df is None:
                continue
            cols = {"time": df.index.to_numpy()}
            cols.update({k: (list(df[k]) if k in TEXT_COLUMNS else df[k].to_numpy()) for k in df.columns})
            write_table(d / name, cols)
            if sto and name != COORDINATES_CSV:  # its OpenSim twin is coordinates.mot (openfdk run)
                csv_to_sto(d / name)
        write_json(d / SUMMARY_JSON, self.summary)
        self.directory = d
        return d

    # ------------------------------------------------------------------ views
    @property
    def time(self) -> np.ndarray:
        """``(n_frames,) s``."""
        return self.kinematics.index.to_numpy()

    @property
    def fdk(self):
        """DataFrame of the FDK solver's columns of forces.csv, indexed by time, the unit
        in each DOF column's name: ``fdk.<dof>.alpha_m`` (``_rad`` for an angle, ``_1``
        dimensionless), ``fdk.<dof>.residual_N`` (``_Nm`` conjugate to an angle), and the
        per-frame ``fdk_converged``, ``fdk_iterations``, ``fdk_evaluations``,
        ``fdk_jacobians``, ``fdk_restarts``, ``fdk_backward``, ``fdk_reason``. A model's force elements
        whose names start with ``fdk`` (springs such as ``fdk_spring_r``) are not FDK
        columns and stay in ``.forces``. Without the model the DOF columns keep the
        names of forces.csv (``.alpha``, ``.residual``, SI). None without FDK DOFs."""
        if self.forces is None:
            return None
        dofs = self.fdk_dofs()
        if not dofs:
            return None
        cols = [c for d in dofs for c in (f"fdk.{d}.alpha", f"fdk.{d}.residual")]
        cols += [c for c in FDK_FRAME_COLUMNS if c in self.forces.columns]
        table = self.forces[cols]
        kinds = self._fdk_kinds()
        if kinds is None:
            return table
        names = {}
        for d in dofs:
            kind = kinds.get(d, "1")
            names[f"fdk.{d}.alpha"] = f"fdk.{d}.alpha_{_SUFFIX[kind]}"
            names[f"fdk.{d}.residual"] = f"fdk.{d}.residual_{_CONJUGATE_SUFFIX[kind]}"
        return table.rename(columns=names)

    def _fdk_kinds(self):
        """FDK DOF name -> measure kind (length / angle / 1), from the model; None
        without it."""
        try:
            model = self.model()
        except Exception:  # a model file that no longer reads: the SI names of forces.csv
            return None
        if model is None:
            return None
        return {d.name: (d.measure.units[0] if d.measure.units else "1") for d in model.fdk_dofs}

    @property
    def failed_frames(self):
        """DataFrame of every frame that failed at any stage: columns ``frame``,
        ``time`` (s), ``stage`` (kinematics / inverse_dynamics / fdk) and ``reason``."""
        import pandas as pd

        rows = []
        k = self.kinematics
        for i in np.flatnonzero(k["converged"].to_numpy() == 0):
            rows.append((int(i), float(k.index[i]), "kinematics", str(k["message"].iloc[i])))
        if self.forces is not None:
            f = self.forces
            kin_failed = set(int(r[0]) for r in rows)
            for i in np.flatnonzero(f["converged"].to_numpy() == 0):
                if int(i) in kin_failed:
                    continue
                status = str(f["status"].iloc[i])
                stage = "fdk" if status.startswith("fdk") else "inverse_dynamics"
                rows.append((int(i), float(f.index[i]), stage, str(f["message"].iloc[i]) or status))
        return pd.DataFrame(sorted(rows), columns=["frame", "time", "stage", "reason"])

    # ------------------------------------------------------------------ column groups
    def bodies(self) -> list[str]:
        """Names of the bodies whose pose is in kinematics.csv."""
        return [c[:-4] for c in self.kinematics.columns if c.endswith(".x_m")]

    def measure_names(self) -> list[str]:
        """Names of the measures in measures.csv (``gap_l``, ``knee.angle``, …)."""
        if self.measures is None:
            return []
        names = [c.rpartition("_")[0].split("[")[0] for c in self.measures.columns]
        return list(dict.fromkeys(names))

    def markers(self) -> list[str]:
        return [c[: -len(".residual_x_m")] for c in self.kinematics.columns if c.endswith(".residual_x_m")]

    def _force_names(self, suffix, exclude_prefix=None) -> list[str]:
        if self.forces is None:
            return []
        out = [c[: -len(suffix)] for c in self.forces.columns if c.endswith(suffix)]
        return [n for n in out if not (exclude_prefix and n.startswith(exclude_prefix))]

    def muscles(self) -> list[str]:
        return self._force_names(".activation")

    def ligaments(self) -> list[str]:
        return self._force_names(".strain")

    def springs(self) -> list[str]:
        return self._force_names(".force")

    def contacts(self) -> list[str]:
        return self._force_names(".Fx_N")

    def actuators(self) -> list[str]:
        """Actuators (reserve and residual actuators; columns ``.actuator``, ``.control``)."""
        return self._force_names(".actuator")

    def reactions(self) -> list[str]:
        """Joint/constraint reaction rows (FDK residual columns excluded)."""
        return self._force_names(".reaction", exclude_prefix="fdk.")

    def fdk_dofs(self) -> list[str]:
        return [n[4:] for n in self._force_names(".alpha") if n.startswith("fdk.")]

    # ------------------------------------------------------------------ the model
    def model(self):
        """The analysed model: the one in memory, or loaded from the model file named in
        summary.json (``input.model_file``, else ``input.model`` relative to the current
        folder or to the result folder). None when it cannot be found."""
        if self._model is None:
            self._model = self._load_model()
        return self._model

    def model_path(self):
        """Path of the model file recorded in summary.json, if it exists."""
        inp = self.summary.get("input", {})
        candidates = []
        for key in ("model_file", "model"):
            if inp.get(key):
                p = Path(inp[key])
                candidates += [p] + ([self.directory / p, self.directory.parent / p] if self.directory else [])
        return next((p for p in candidates if p.is_file()), None)

    def _load_model(self):
        from ..io.modelfile import load_model_for_results

        path = self.model_path()
        return load_model_for_results(path, self.summary) if path is not None else None

    def __repr__(self):
        s = self.summary.get("kinematics", {})
        return (f"RunResults({s.get('model', '?')!r}: {len(self.kinematics)} frames, "
                f"{len(self.failed_frames)} failed, folder={str(self.directory) if self.directory else None})")


def read_results(directory, model=None) -> RunResults:
    """Load a saved run (``openfdk run --out DIR`` or :meth:`RunResults.save`); ``model``:
    its Model if already loaded (:meth:`RunResults.read`)."""
    return RunResults.read(directory, model)
