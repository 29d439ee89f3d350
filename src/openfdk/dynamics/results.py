"""Inverse-dynamics results of a trial and the per-frame values they are built from.

The trial driver (:mod:`openfdk.trial`) records, per frame, the values returned by
:func:`forces_values` (a solved frame) or :func:`forces_failure` (a frame without
forces) under a prefix; :func:`forces_result` builds the immutable
:class:`InverseDynamicsResult` once, at the end.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..trial.status import FrameReport, Reason, frame_messages

#: recorded per-frame fields of the forces (after the prefix) other than contact columns
_ARRAYS = ("f", "muscle_length", "muscle_speed", "muscle_strength", "muscle_passive", "ligament_length",
           "ligament_strain", "ligament_force", "spring_force")
COLUMN = "col."  # prefix of the extra per-frame columns (contacts) within the forces fields
#: the forces.csv columns of a measured external load (``<load>.<key>``): its force and the
#: point where it acts, in the world (N, m), as applied at the frame's pose
EXTERNAL_LOAD_KEYS = ("external_Fx_N", "external_Fy_N", "external_Fz_N", "external_px_m", "external_py_m",
                      "external_pz_m")


@dataclass(frozen=True)
class InverseDynamicsResult:
    """Forces over a trial. forces : (nf, n_columns) N; column_names;
    muscle_length/speed/strength/passive : (nf, n_muscles); ligament_* and spring_* :
    (nf, n); converged (nf,) bool; status (recruitment status code per frame);
    reports : FrameReport per frame; iterations (nf,) recruitment iterations;
    messages : per-frame text from the reports ('' when converged);
    actuator_names : the actuators (their columns follow the muscles'), with their
    optimal forces actuator_optimal_force (n_act,) N or N m."""

    time: np.ndarray
    column_names: tuple
    muscle_names: tuple
    n_bounded: int
    forces: np.ndarray
    muscle_length: np.ndarray
    muscle_speed: np.ndarray
    muscle_strength: np.ndarray
    muscle_passive: np.ndarray
    ligament_names: tuple
    ligament_length: np.ndarray
    ligament_strain: np.ndarray
    ligament_force: np.ndarray
    spring_names: tuple
    spring_force: np.ndarray
    converged: np.ndarray
    status: tuple
    reports: tuple
    iterations: np.ndarray
    wall_time: float = 0.0
    extra: dict = field(default_factory=dict)
    actuator_names: tuple = ()
    actuator_optimal_force: np.ndarray = None

    @property
    def messages(self):
        return frame_messages(self.reports, self.time)

    def failed_frames(self):
        msgs = self.messages
        return [(int(i), float(self.time[i]), msgs[i]) for i in np.flatnonzero(~self.converged)]

    def summary(self):
        return {
            "frames": int(len(self.time)),
            "converged_frames": int(np.sum(self.converged)),
            "failed_frames": [{"frame": i, "time": t, "reason": m} for i, t, m in self.failed_frames()],
            "mean_recruitment_iterations": float(np.mean(self.iterations)) if len(self.iterations) else 0.0,
            "wall_time_s": self.wall_time,
        }


def forces_fields(solver, prefix="dyn."):
    """Declared per-frame fields {name: (shape, dtype, fill)} of a solver's forces."""
    lay, model = solver.layout, solver.model
    nm, nl, ns = lay.n_muscles, len(model.ligaments), len(model.springs)
    shapes = {"f": (lay.n_columns,), "muscle_length": (nm,), "muscle_speed": (nm,), "muscle_strength": (nm,),
              "muscle_passive": (nm,), "ligament_length": (nl,), "ligament_strain": (nl,),
              "ligament_force": (nl,), "spring_force": (ns,)}
    out = {prefix + k: (s, float, np.nan) for k, s in shapes.items()}
    out[prefix + "status"] = ((), object, "kinematics_failed")
    out[prefix + "iterations"] = ((), int, 0)
    out[prefix + "report"] = ((), object, None)
    return out


def forces_values(fr, prefix="dyn.", report=None, status=None):
    """Per-frame values of a solved frame (fr: FrameForces). ``report``/``status``
    replace the recruitment's own (FDK marks frames whose α did not converge)."""
    lig, spr = fr.forces.get("ligaments"), fr.forces.get("springs")
    none = np.zeros(0)
    values = {"f": fr.f, "muscle_length": fr.muscle_length, "muscle_speed": fr.muscle_speed,
              "muscle_strength": fr.muscle_strength, "muscle_passive": fr.muscle_passive,
              "ligament_length": none if lig is None else lig.length,
              "ligament_strain": none if lig is None else lig.strain,
              "ligament_force": none if lig is None else lig.force,
              "spring_force": none if spr is None else spr.force,
              "status": fr.status if status is None else status, "iterations": fr.iterations}
    if report is None:
        res = fr.recruitment
        resid = float(np.abs(res.residual).max()) if res is not None and np.size(res.residual) else np.nan
        report = (FrameReport.ok(fr.iterations, resid) if fr.converged
                  else FrameReport.failed(Reason.RECRUITMENT, fr.message, fr.iterations, resid))
    values["report"] = report
    for name, c in fr.forces.get("contacts", {}).items():
        # force on the vertex body (world, N), centre of pressure (m), area (m²), peak
        # pressure (Pa), vertices in contact
        for key, v in (("Fx_N", c.force_W[0]), ("Fy_N", c.force_W[1]), ("Fz_N", c.force_W[2]),
                       ("cop_x_m", c.cop_W[0]), ("cop_y_m", c.cop_W[1]), ("cop_z_m", c.cop_W[2]),
                       ("area_m2", c.area), ("peak_pressure_Pa", c.peak_pressure), ("n_contact", c.n_contact)):
            values[f"{COLUMN}{name}.{key}"] = float(v)
        for region, F in (c.region_force_W or {}).items():  # |force| of each region (N)
            values[f"{COLUMN}{name}.{region}_N"] = float(np.linalg.norm(F))
    for name, (F_W, p_WP, _) in fr.forces.get("external_loads", {}).items():
        # a measured load (a ground reaction) as applied: force (world, N) and its point (world, m)
        for key, v in zip(EXTERNAL_LOAD_KEYS, (*F_W, *p_WP)):
            values[f"{COLUMN}{name}.{key}"] = float(v)
    return {prefix + k: v for k, v in values.items()}


def forces_failure(report, status, prefix="dyn."):
    """Per-frame values of a frame without forces (NaN forces)."""
    return {prefix + "status": status, prefix + "iterations": 0, prefix + "report": report}


def forces_result(rec, solver, time, wall_time, prefix="dyn.", extra_columns=None):
    """The InverseDynamicsResult of a Recording (frames in ``time`` (nf,) s)."""
    lay, model = solver.layout, solver.model
    a = {k: rec.array(prefix + k) for k in _ARRAYS}
    reports = rec.objects(prefix + "report")
    cols = {name[len(prefix + COLUMN):]: rec.array(name) for name in rec.names()
            if name.startswith(prefix + COLUMN)}
    cols.update(extra_columns or {})
    converged = np.array([r.converged for r in reports], dtype=bool)
    converged.setflags(write=False)
    return InverseDynamicsResult(
        np.asarray(time), lay.column_names, tuple(m.name for m in lay.muscles), lay.n_bounded, a["f"],
        a["muscle_length"], a["muscle_speed"], a["muscle_strength"], a["muscle_passive"],
        tuple(x.name for x in model.ligaments), a["ligament_length"], a["ligament_strain"], a["ligament_force"],
        tuple(x.name for x in model.springs), a["spring_force"], converged, rec.objects(prefix + "status"), reports,
        rec.array(prefix + "iterations"), wall_time, {"columns": cols},
        tuple(a.name for a in lay.actuators), np.array([a.optimal_force for a in lay.actuators], float),
    )
