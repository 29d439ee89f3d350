"""The paper's TMJ ligament parameter study (docs/design.md §2) run through openfdk's study
machinery (:mod:`openfdk.study`), and the grey bands of Figures 5–7 built from it.

The 15 FDK models are the comparison model file ``fdk.yaml`` with two overrides on
every ligament element: the whole-ligament stiffness k ∈ {136.2, 272.4, 544.8} N/m,
split equally over the 3 elements of a side, and the reference strain
ε_r ∈ {−0.04, −0.02, 0, 0.02, 0.04}. Each (model, task) pair is one independent case of
one study, so the cases run in parallel on a LocalCluster (or any Dask scheduler),
publish their folders atomically under ``parameter_study/cases/`` and are skipped when
the study is run again; ``parameter_study/summary.csv`` has one row per case.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..study.spec import study_from_dict
from ..study.summary import read_table
from .extract import SIDE_TAGS, compared_condyle_point, skull_frame_forces, skull_frame_points
from .models import PARAMETER_STUDY_STIFFNESS, PARAMETER_STUDY_STRAIN

ELEMENTS_PER_SIDE = 3
STUDY_NAME = "tmj-ligament-parameter-study"


def parameter_grid(quick=False):
    """The grid {parameter: values}: 3 stiffnesses (N/m, whole ligament) × 5 reference
    strains = 15 models; quick: the stiffness extremes at zero reference strain."""
    if quick:
        return {"stiffness": [PARAMETER_STUDY_STIFFNESS[0], PARAMETER_STUDY_STIFFNESS[-1]], "reference_strain": [0.0]}
    return {"stiffness": list(PARAMETER_STUDY_STIFFNESS), "reference_strain": list(PARAMETER_STUDY_STRAIN)}


def parameter_study(fdk_model, windows, quick=False):
    """The study (:class:`openfdk.study.Study`) of the FDK model file ``fdk_model`` over
    ``windows`` {task: (trial C3D path, start s, end s)}: one case per (model variant,
    task), analysed over that task's window, ids ``fdk-<task>-<k>``."""
    cases, study = [], None
    for task, (trial, start, end) in windows.items():
        data = {
            "openfdk_study": 1, "name": STUDY_NAME,
            "models": {"fdk": str(Path(fdk_model).resolve())}, "trials": {task: str(Path(trial).resolve())},
            "parameters": {
                "stiffness": {"set": "ligaments.*.stiffness", "scale": 1.0 / ELEMENTS_PER_SIDE},
                "reference_strain": "ligaments.*.reference_strain",
            },
            "grid": parameter_grid(quick),
            "run": {"start": float(start), "end": float(end), "retries": 1,
                    "metrics": [f"tmj_{t}.F{c}_N" for t in SIDE_TAGS.values() for c in "xyz"]},
        }
        study = study_from_dict(data, source=f"{STUDY_NAME} ({task})", base_dir=Path(fdk_model).parent)
        cases += study.cases
    if study is None:
        raise ValueError("parameter study: no task given")
    return replace(study, cases=tuple(cases))


def run_parameter_study(fdk_model, windows, out_dir, quick=False, workers=None, scheduler=None, progress=True):
    """Run :func:`parameter_study` into ``out_dir`` (default: a LocalCluster with one
    worker per CPU; ``workers=0`` in this process). Returns the StudyResult."""
    from ..study.runner import run_study

    return run_study(parameter_study(fdk_model, windows, quick), out_dir, workers=workers, scheduler=scheduler,
                     progress=progress)


def case_tmj_series(folder, subject):
    """(time (nf,) s, kinematics {side: (nf, 3) m}, forces {side: (nf, 3) N}) of one
    complete case folder, in the skull frame: condyle-top displacements from the
    reference pose and contact forces on the mandible (as the main FDK model's)."""
    kin = read_table(Path(folder) / "kinematics.csv")
    forces = read_table(Path(folder) / "forces.csv")
    q_S, q_M = (np.column_stack([kin[f"{b}.{c}"] for c in ("x_m", "y_m", "z_m", "e0", "e1", "e2", "e3")])
                for b in ("skull", "mandible"))
    points = skull_frame_points(q_S, q_M, subject)
    ref = {side: compared_condyle_point(subject, tag) for side, tag in SIDE_TAGS.items()}
    displacement = {side: p - ref[side] for side, p in points.items()}
    return kin["time"], displacement, skull_frame_forces(forces, q_S)


def parameter_bands(result, subject, cycles_by_task, n_points=101):
    """Grey bands of the figures from a finished StudyResult: task -> kinematics/forces
    -> side -> (n_cases, n_points, 3), each case's mean normalised cycle, using the
    measured cycles of the main analysis ``cycles_by_task`` {task: (time (nf,) s, cycle
    index pairs)}. Failed cases are left out (they are listed in the study summary)."""
    from .cycles import normalize_cycles

    bands = {}
    for rec in result.records:
        if rec["status"] != "completed":
            continue
        task = rec["names"]["trials"]
        if task not in cycles_by_task:
            continue
        time, cycles = cycles_by_task[task]
        t, kin, forces = case_tmj_series(result.out_dir / "cases" / rec["case_id"], subject)
        if len(t) != len(time) or np.max(np.abs(t - time)) > 1e-9:
            raise ValueError(f"parameter study case {rec['case_id']}: its frames differ from the main analysis of {task}")
        for group, data in (("kinematics", kin), ("forces", forces)):
            for side, arr in data.items():
                mean = np.nanmean(normalize_cycles(t, arr, cycles, n_points), axis=0)
                bands.setdefault(task, {}).setdefault(group, {}).setdefault(side, []).append(mean)
    return {task: {group: {side: np.array(v) for side, v in sides.items()} for group, sides in groups.items()}
            for task, groups in bands.items()}
