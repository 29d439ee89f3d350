"""``measures.csv``: every named measure of a model over a trial's frames.

Named measures are those of the model file's ``measures`` section and the joints'
measures (``knee.angle``, ``knee.position``, ``knee.angles``, …). Columns are
``name_unit`` for a scalar and ``name[k]_unit`` per component (SI: m, rad, 1), first
column ``time``; a frame whose pose did not converge, or where a measure cannot be
evaluated (e.g. gimbal lock), gets NaN.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .results import write_table

UNIT_SUFFIX = {"length": "m", "angle": "rad", "1": "1"}


def measure_columns(model, kinematics):
    """{column: (nf,) values} of every named measure at the poses of ``kinematics``
    (a KinematicsResult: time (nf,), q (nf, 7 n_moving), converged (nf,))."""
    names = sorted(model.measures)
    state = model.initial_state()
    nf = len(kinematics.time)
    values = {n: np.full((nf, model.measures[n].size), np.nan) for n in names}
    for i in range(nf):
        if not kinematics.converged[i]:
            continue
        state.set_q(kinematics.q[i])
        for n in names:
            try:
                values[n][i] = model.measures[n].evaluate(state, 0)[0]
            except FloatingPointError:
                pass
    cols = {"time": kinematics.time}
    for n in names:
        m = model.measures[n]
        for k in range(m.size):
            label = n if m.size == 1 else f"{n}[{k}]"
            cols[f"{label}_{UNIT_SUFFIX.get(m.units[k], '1')}"] = values[n][:, k]
    return cols


def write_measures(out_dir, model, kinematics):
    """Write ``measures.csv`` into ``out_dir`` when the model has named measures."""
    if not model.measures:
        return None
    path = Path(out_dir) / "measures.csv"
    write_table(path, measure_columns(model, kinematics))
    return path
