"""``openfdk check``: what a model contains, and whether it can run, before it runs.

The report lists bodies, joints, constraints, drivers, FDK DOFs, markers, muscles,
ligaments, springs, contacts, loads and unilateral reactions; counts constraint rows
(joints + drivers + FDK DOFs, paper Eq. 1) against the 6 n_moving coordinates q̂; and
takes the rank of the constraint Jacobian Φ_q̂ at the reference pose (FDK DOFs at their
initial α), as ``run`` does per frame:

* rows in a linear dependency (left null space of Φ_q̂) are *redundant* and named;
* coordinates in the right null space are *free*; without markers the kinematics are
  then undetermined (named). With markers the marker Jacobian Ψ_q̂ (Eq. 4) is stacked
  under Φ_q̂ first, because marker tracking can fix what the constraints leave free.

Muscle and ligament paths are evaluated at the reference pose too; a path that cannot be
formed there (e.g. an attachment inside a wrapping surface) is listed as a warning, since
the assembled poses of a run may differ. Either rank problem makes the model unable to run: :func:`check_model` returns them as
errors and the command exits with code 2.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field

import numpy as np

from ..kinematics.system import ConstraintSystem, dependent_rows, undetermined_coordinates
from ..model.constraints import DRIVER


@dataclass
class CheckReport:
    """lines : the printable summary; errors : one-line reasons the model cannot run."""

    lines: list = field(default_factory=list)
    errors: list = field(default_factory=list)

    @property
    def ok(self):
        return not self.errors

    def text(self):
        return "\n".join(self.lines + [f"ERROR: {e}" for e in self.errors])


def _names(items):
    return ", ".join(items) if items else "-"


def _label(element):
    """Element name, with the wrapping surfaces its path passes over."""
    nodes = getattr(getattr(element, "path", None), "nodes", None)
    surfaces = [n.name for n in nodes or () if hasattr(n, "kind")]
    return f"{element.name} over {'+'.join(surfaces)}" if surfaces else element.name


def _reference_time(model):
    """A time (s) at which every driver is defined: 0, or the latest start of a driver
    that follows data and is not extrapolated (a ``--motion`` file starting at 0.5 s).
    Φ_q̂ does not depend on it; the drivers' targets are evaluated with it."""
    from ..model.timefunctions import sampled_time_range

    start, _ = sampled_time_range(c.function for c in model.constraints if c.kind == DRIVER)
    return float(start) if start > 0.0 else 0.0


def reference_jacobian(model, state=None):
    """(Φ_q̂ (m, n), its m row names) at the reference pose, FDK DOFs at their initial α
    (at :func:`_reference_time`)."""
    system = ConstraintSystem(model)
    alpha = np.array([d.initial for d in model.fdk_dofs], dtype=float)
    _, A, _, _ = system.evaluate(model.initial_state() if state is None else state, _reference_time(model), alpha,
                                 order=1)
    return A, system.row_names


def _reference_rank(model, state=None):
    """(Φ_q̂, its rank, the names of the rows in a linear dependency) at the reference
    pose (:func:`reference_jacobian`)."""
    A, row_names = reference_jacobian(model, state)
    rank, redundant = dependent_rows(A, row_names)
    return A, rank, redundant


def markers_move_nothing(model):
    """Whether the model's own rows (joints, constraints, drivers such as a motion
    file's, FDK DOFs) determine every coordinate at the reference pose: marker tracking
    then has nothing to fit, and the markers of a trial move nothing. False when the rows
    cannot be evaluated there (the run reports why)."""
    try:
        A, _ = reference_jacobian(model)
    except (FloatingPointError, ValueError):
        return False
    if A.shape[0] < A.shape[1] or A.shape[1] == 0:
        return False
    s = np.linalg.svd(A, compute_uv=False)
    return bool(s[-1] > 1e-9 * s[0])


def _redundant_message(rank, rows, redundant):
    return (f"constraint Jacobian is singular at the reference pose (rank {rank} of {rows} rows): "
            f"redundant or inconsistent rows {redundant}")


def refuse_redundant_rows(model, source=""):
    """``check``'s rank test, done by ``run`` and ``kinematics`` before the first frame:
    a ModelError naming ``source`` (the model file) and the rows in a linear dependency
    at the reference pose. A model whose constraints cannot be evaluated there is left
    to the run (its frames report why)."""
    from ..model.model import ModelError

    found = _RANKS.get(model)
    if found is None:  # a property of the (immutable) model: found once, not at every run of it
        try:
            A, rank, redundant = _reference_rank(model)
        except (FloatingPointError, ValueError):
            return
        found = _RANKS[model] = (A.shape[0], rank, tuple(redundant))
    rows, rank, redundant = found
    if redundant:
        prefix = f"{source}: " if source else ""
        raise ModelError(f"{prefix}{_redundant_message(rank, rows, list(redundant))} (see `openfdk check`)")


_RANKS = weakref.WeakKeyDictionary()  # model -> (rows, rank, redundant rows) at the reference pose


def _check_contact_meshes(model, rep):
    """The contact-mesh table (:mod:`openfdk.contact.mesh_check`): its lines, its
    warnings as ``warning:`` lines, its refusals as errors."""
    from ..contact.mesh_check import check_contacts, table

    checks = check_contacts(model)
    rep.lines.extend(table(checks))
    for chk in checks:
        rep.lines.extend(f"  warning: {w}" for w in chk.warnings)
        rep.errors.extend(chk.errors)


def _check_absorbed_muscles(model, rep, state):
    """A warning line naming the muscles FDK can never recruit (:mod:`openfdk.fdk.absorbed`)."""
    if not model.fdk_dofs or not model.muscles:
        return
    from ..dynamics.inverse import InverseDynamics
    from ..fdk.absorbed import absorbed_message, fdk_absorbed_muscles

    try:
        names = fdk_absorbed_muscles(InverseDynamics(model, ConstraintSystem(model)), state)
    except (FloatingPointError, ValueError, np.linalg.LinAlgError):
        return  # the rank checks below report what stops the model
    if names:
        rep.lines.append(f"  warning: {absorbed_message(names)}")


def _free(model, state, A):
    """Names of what the rows A (m, 6 n_moving) leave free at ``state``: a model's joint
    coordinates that can move along A's null space (an OpenSim model's
    ``mtp_angle_r``), else, or when no coordinate moves along all of it, the bodies'
    components (``toes_r.rx``)."""
    from ..kinematics.system import null_space

    null = null_space(A)
    if null.shape[1] == 0:
        return []
    if model.coordinates:
        try:
            G = np.vstack([np.atleast_2d(c.measure.evaluate(state, 1)[1])[:1] for c in model.coordinates])
        except (FloatingPointError, ValueError, np.linalg.LinAlgError):  # a coordinate undefined here: the bodies
            return undetermined_coordinates(A, model.coordinate_names())
        moved = np.linalg.norm(G @ null, axis=1) > 1e-6 * np.maximum(np.linalg.norm(G, axis=1), 1.0)
        # every free direction must move some coordinate, else name the bodies
        if moved.any() and np.linalg.matrix_rank(G[moved] @ null, tol=1e-9) == null.shape[1]:
            return [c.name for c, m in zip(model.coordinates, moved) if m]
    return undetermined_coordinates(A, model.coordinate_names())


def check_model(model):
    """Inventory, row count and rank at the reference pose of ``model`` (CheckReport)."""
    rep = CheckReport()
    moving = [b.name for b in model.moving_bodies]
    fixed = [b.name for b in model.bodies if b.column < 0]
    joints = [c for c in model.constraints if c.kind != DRIVER and c.joint_type != "generic"]
    generic = [c for c in model.constraints if c.kind != DRIVER and c.joint_type == "generic"]
    drivers = [c for c in model.constraints if c.kind == DRIVER]
    rep.lines.append(f"model {model.name!r}")
    rep.lines.append(f"  bodies: {len(moving)} moving ({_names(moving)}), fixed: {_names(fixed)}")
    rep.lines.append(f"  joints: {_names([f'{c.name} ({c.joint_type}, {c.size} rows)' for c in joints])}")
    rep.lines.append(f"  constraints: {_names([f'{c.name} ({c.size} rows)' for c in generic])}")
    rep.lines.append(f"  drivers: {_names([f'{c.name} ({c.size} rows)' for c in drivers])}")
    rep.lines.append(f"  FDK DOFs: {_names([d.name for d in model.fdk_dofs])}")
    rep.lines.append(f"  markers: {model.markers.size}")
    for label, key in (("muscles", "muscles"), ("ligaments", "ligaments"), ("springs", "springs"),
                       ("contacts", "contacts"), ("loads", "loads"), ("unilateral reactions", "unilateral_reactions")):
        items = getattr(model, key)
        rep.lines.append(f"  {label}: {len(items)}" + (f" ({_names([_label(x) for x in items])})" if items else ""))
    state = model.initial_state()
    for key in ("muscles", "ligaments"):
        for item in getattr(model, key):
            try:
                item.path.evaluate(state, 0)
            except (FloatingPointError, ValueError) as exc:
                rep.lines.append(f"  warning: {key[:-1]} {item.name!r} at the reference pose: {exc}")
    _check_contact_meshes(model, rep)
    _check_absorbed_muscles(model, rep, state)
    n = model.n_coords
    n_joint = sum(c.size for c in model.constraints if c.kind != DRIVER)
    n_driver = sum(c.size for c in drivers)
    n_fdk = len(model.fdk_dofs)
    rows = n_joint + n_driver + n_fdk
    rep.lines.append(f"  rows: {n_joint} joint/constraint + {n_driver} driver + {n_fdk} FDK = {rows}; "
                     f"coordinates: {n} (6 per moving body)")
    try:
        A, rank, redundant = _reference_rank(model, state)
    except (FloatingPointError, ValueError) as exc:
        rep.errors.append(f"the constraints cannot be evaluated at the reference pose: {exc}")
        return rep
    rep.lines.append(f"  rank of the constraint Jacobian at the reference pose: {rank} of {rows} rows")
    if redundant:
        rep.errors.append(_redundant_message(rank, rows, redundant))
    determined = not redundant and rows >= n and rank == n
    if model.markers.size and determined:  # a motion file drives a model with markers: they move nothing
        rep.lines.append("  kinematics: determinate (drivers and FDK DOFs fix every coordinate; a trial's markers "
                         "would move nothing)")
    elif model.markers.size:
        _, Psi_q, _ = model.markers.evaluate(state, 1)
        Psi_q = Psi_q[np.repeat(model.markers.weight > 0, 3)]  # a marker of weight 0 is not tracked
        tasks = [np.atleast_2d(t.measure.evaluate(state, 1)[1]) for t in model.tasks if t.weight > 0]
        free = _free(model, state, np.vstack([A, Psi_q, *tasks]))
        what = "markers and coordinate tasks" if model.tasks else "markers"
        if free:
            named = model.coordinates and set(free) <= {c.name for c in model.coordinates}
            hint = (f" (give OpenSim's IK tasks with --ik-tasks, or hold them with 'lock: [{', '.join(free)}]' in an "
                    "overlay, --with FILE)" if named else
                    " (give OpenSim's IK tasks with --ik-tasks, or lock the coordinates)" if model.coordinates else "")
            rep.errors.append(f"constraints and {what} leave coordinates free at the reference pose: {free}{hint}")
        else:
            rep.lines.append(f"  kinematics: marker tracking; constraints and {what} determine every coordinate")
    else:
        free = _free(model, state, A)
        if free:
            fix = ("give a trial of the model's markers, or drive every coordinate from a coordinate file with "
                   "--motion FILE (as OpenSim's inverse dynamics does)" if model.coordinates else
                   "add joints, drivers or FDK DOFs")
            rep.errors.append(f"{n - rank} coordinate(s) free at the reference pose, no markers to track them: "
                              f"{fix}; free: {free}")
        elif not redundant:
            rep.lines.append("  kinematics: determinate (drivers and FDK DOFs fix every coordinate)")
    return rep


__all__ = ["CheckReport", "check_model", "refuse_redundant_rows"]
