"""Plausibility checks of a loaded model, of a trial against it and of a run's results.

Errors (physically impossible, :class:`~openfdk.model.model.ModelError`):

- a body's principal moments of inertia must be positive and satisfy the triangle
  inequality I₁ + I₂ ≥ I₃ (a rigid body's mass distribution cannot give anything else:
  I₁ + I₂ − I₃ = 2 ∫ z² dm ≥ 0 along the third principal axis);
- masses above 1e6 kg and moments of inertia above 1e6 kg m² (a musculoskeletal segment
  is 1e-3 to 1e2 kg; the recruitment LP cannot scale 1e300).

Warnings (:class:`PlausibilityWarning`, each naming the item):

- magnitudes implausible for the declared length unit, with the likely unit;
- a Hill muscle whose passive force at the reference pose exceeds 10 % of F0;
- a marker never visible in the analysis window; trial markers far from the model's at
  the first frame, or spanning a very different size (likely the wrong units);
- a contact force that pulls the two surfaces together (once per run, see
  :func:`pulling_contacts`);
- a tracked marker whose residual over a run is far above the others' (mislabelled, or
  placed elsewhere on the model: :func:`outlier_markers`).

Contact meshes whose normals face away from their partner are checked, and refused, by
:mod:`openfdk.contact.mesh_check` before a run.
"""

from __future__ import annotations

import warnings

import numpy as np

from .model import ModelError

#: largest accepted body mass (kg) and principal moment of inertia (kg m²)
MAX_MASS = 1e6
MAX_INERTIA = 1e6
#: a Hill muscle's passive force at the reference pose above this fraction of F0 is flagged
PASSIVE_FRACTION = 0.10
#: plausible span (m) of a musculoskeletal model's points: a finger joint to a whole body
MODEL_SPAN = (2e-3, 20.0)
TYPICAL_SPAN = 0.3
#: trial markers whose centroid lies farther (m) from the model's are flagged (no lab is larger)
FAR_FROM_MODEL = 20.0
#: a tracked marker's RMS residual over a run is flagged above this many times the
#: tracked markers' median and above OUTLIER_MIN (m): skin motion gives 1–2 cm
OUTLIER_FACTOR, OUTLIER_MIN = 3.0, 0.03
LENGTH_SCALES = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}


class PlausibilityWarning(UserWarning):
    """Input that is possible but probably wrong (units, orientation, parameters)."""


class RawGroundReactionWarning(PlausibilityWarning):
    """Ground reactions whose samples look unfiltered (:mod:`openfdk.forces.data_load_section`):
    a matter for the runs that apply them, not for a kinematics pass."""


def _warn(msg):
    warnings.warn(msg, PlausibilityWarning, stacklevel=3)


def warn_plausibility(msg, category=PlausibilityWarning):
    """Issue one plausibility warning (printed by the CLI as ``openfdk: warning: msg``);
    ``category``: PlausibilityWarning or a subclass."""
    warnings.warn(msg, category, stacklevel=3)


# -- model ------------------------------------------------------------------------------

def check_model(model, source="", length_unit="m"):
    """All load-time checks of ``model`` (errors raise ModelError, the rest warn).
    ``source`` is the file name used in messages, ``length_unit`` the declared unit."""
    check_mass_properties(model, source)
    check_length_magnitudes(model, source, length_unit)
    check_passive_muscles(model, source, length_unit)
    check_fdk_held(model, source)


def _where(source, path):
    return f"{source}: {path}" if source else path


def principal_moments(inertia):
    """(3,) kg m², ascending: the principal moments of the symmetric part of ``inertia``
    (3, 3) kg m² (scaled first: eigvalsh fails on entries near the float limit)."""
    inertia = np.asarray(inertia, float)
    scale = float(np.max(np.abs(inertia))) or 1.0
    unit = inertia / scale
    return np.linalg.eigvalsh(0.5 * (unit + unit.T)) * scale


def breaks_triangle_inequality(moments):
    """Whether principal moments (3,) ascending break I1 + I2 >= I3: no rigid body has them."""
    return bool(moments[0] + moments[1] < moments[2] * (1 - 1e-9))


def check_mass_properties(model, source=""):
    """Masses and inertias physically possible (module docstring); raises ModelError."""
    for b in model.bodies:
        if b.fixed:
            continue
        where = _where(source, f"bodies.{b.name}")
        if b.mass > MAX_MASS:
            raise ModelError(f"{where}.mass: {b.mass:g} kg is not a plausible body mass (at most {MAX_MASS:g} kg)")
        I = principal_moments(b.inertia_B)
        if I[-1] > MAX_INERTIA:
            raise ModelError(f"{where}.inertia: principal moment {I[-1]:g} kg m² is not plausible "
                             f"(at most {MAX_INERTIA:g} kg m²)")
        if breaks_triangle_inequality(I):
            text = (f"{where}.inertia: principal moments {np.round(I, 12).tolist()} kg m² violate the triangle "
                    "inequality I1 + I2 >= I3; no rigid body has this inertia")
            if not b.inertia_as_given:
                raise ModelError(text)
            _warn(f"{text}; used as given (inertia_as_given), as OpenSim uses it")


def _reference_points(model):
    """(n, 3) m: body centres of mass, frames and markers at the reference pose."""
    state = model.initial_state()
    pts = [b.p_WB0 for b in model.bodies if b.name != "ground"]
    for f in model.frames.values():
        i = next(k for k, b in enumerate(model.bodies) if b.name == f.body)
        pts.append(state.p_WB[i] + state.R_WB[i] @ f.p_BF)
    if model.markers.size:
        pts.extend(model.markers.positions(state))
    return np.array(pts, dtype=float).reshape(-1, 3)


def _likely_unit(span, declared):
    """The length unit under which ``span`` (m, as read with ``declared``) is plausible."""
    raw = span / LENGTH_SCALES.get(declared, 1.0)  # the numbers as written in the file
    fits = [(abs(np.log10(raw * scale / TYPICAL_SPAN)), unit) for unit, scale in LENGTH_SCALES.items()
            if MODEL_SPAN[0] <= raw * scale <= MODEL_SPAN[1] and unit != declared]
    return min(fits)[1] if fits else None


def check_length_magnitudes(model, source="", length_unit="m"):
    """Warn when the model's points span an implausible size for the declared unit."""
    pts = _reference_points(model)
    if len(pts) < 2:
        return
    span = float(np.max(np.ptp(pts, axis=0)))
    if span == 0.0 or MODEL_SPAN[0] <= span <= MODEL_SPAN[1]:
        return
    likely = _likely_unit(span, length_unit)
    hint = f"; the numbers look like {likely}" if likely else ""
    _warn(f"{_where(source, 'units.length')}: the model's points span {span:.4g} m with lengths declared in "
          f"{length_unit}{hint} (a musculoskeletal model spans {MODEL_SPAN[0] * 1e3:g} mm to {MODEL_SPAN[1]:g} m)")


def check_fdk_held(model, source=""):
    """Warn when a model has FDK DOFs but no spring, bushing, ligament or contact: then
    only the muscles act along the DOFs, the FDK residual (Eq. 16) has no restoring
    force and the Newton iteration cannot converge."""
    if model.fdk_dofs and not (model.springs or model.ligaments or model.contacts):
        names = [d.name for d in model.fdk_dofs]
        _warn(f"{_where(source, 'fdk_dofs')}: no spring, bushing, ligament or contact in the model holds the FDK "
              f"DOFs {names}: their residual has no restoring force and FDK will not converge; add springs "
              "(the paper uses 0.1 N/m), ligaments or contact")


def held_fdk_loops(model):
    """[(constraint name, [FDK DOF names])]: the model's held distances (a constraint of
    a distance measure, e.g. an inextensible patellar tendon) that share a body with FDK
    DOFs. A kinematics pass holds the FDK DOFs at their initial values, and such a row
    then closes a loop those held values shape, with a reach: DM's ``dm_pt.yaml`` stops
    the knee at 30° of flexion in og1's swing, and on the crouch cycle with a motion file
    110 of 152 frames fail at the tendon's row. Constraints that set a body's whole
    position or orientation (the mandible model's hyoid following the mandible) have no
    reach and are not named."""
    from .measures import Distance

    out = []
    for c in model.constraints:
        if c.kind != "joint" or c.joint_type != "generic" or not isinstance(c.measure, Distance):
            continue
        bodies = set(c.measure.bodies())
        shared = [d.name for d in model.fdk_dofs if bodies & set(d.measure.bodies())]
        if shared:
            out.append((c.name, shared))
    return out


def warn_held_fdk_loops(model, source=""):
    """Warn, for a kinematics pass, about each row of :func:`held_fdk_loops`."""
    for name, dofs in held_fdk_loops(model):
        more = f" and {len(dofs) - 3} more" if len(dofs) > 3 else ""
        _warn(f"{_where(source, f'constraints.{name}')}: a kinematics pass holds the FDK DOFs at their initial "
              f"values ({', '.join(dofs[:3])}{more}), and this held distance closes a loop through their bodies: "
              f"the coordinates it couples may stop short of the markers or the motion (a knee's flexion). For the "
              f"first pass of two stages, use the model without it (docs/gait.md, 'The first pass must leave the "
              f"primary coordinates free')")


def check_passive_muscles(model, source="", length_unit="m"):
    """Warn for each Hill or Millard muscle whose passive force at the reference pose exceeds
    PASSIVE_FRACTION of its maximum isometric force F0. When Lf0 + Lt0 is under 1 % of
    the path length, the warning says that these lengths are in the file's length unit
    ``length_unit`` (metres written in a mm file are 1000x too short)."""
    muscles = [m for m in model.muscles if hasattr(m.law, "tendon_slack_length")]  # Hill, Millard
    if not muscles:
        return
    state = model.initial_state()
    for m in muscles:
        length = float(np.ravel(m.path.evaluate(state, 0)[0])[0])
        if not np.isfinite(length):
            continue
        _, passive = m.law.evaluate(length, 0.0)
        F0 = float(m.law.max_isometric_force)
        if np.isfinite(passive) and passive > PASSIVE_FRACTION * F0:
            _warn(f"{_where(source, f'muscles.{m.name}')}: passive force {passive:.4g} N at the reference pose is "
                  f"{100 * passive / F0:.0f} % of max_isometric_force ({F0:g} N); check optimal_fibre_length and "
                  f"tendon_slack_length (path length {length * 1e3:.1f} mm){_muscle_unit_hint(m.law, length, length_unit)}")


def _muscle_unit_hint(law, length, length_unit):
    """A hint when Lf0 + Lt0 (m) is under 1 % of the path ``length`` (m): the muscle's
    lengths were probably written in m in a file whose length unit is smaller."""
    total = float(law.optimal_fibre_length + law.tendon_slack_length)
    if total >= 0.01 * length:
        return ""
    scale = LENGTH_SCALES.get(length_unit, 1.0)
    return (f"; optimal_fibre_length + tendon_slack_length = {total / scale:g} {length_unit} as written: muscle "
            f"lengths are in the file's length unit ({length_unit}), not in m")


# -- trial against model ----------------------------------------------------------------

def check_trial_markers(model, trial, times):
    """Warn for markers never visible in the analysis window ``times`` (nf,) s, and when
    the trial's markers at the first analysed frame are far from the model's markers at
    the reference pose or span a very different size (likely the wrong units).
    ``trial`` is a MarkerTrial already restricted to the model's markers (model order)."""
    t = np.asarray(trial.time, dtype=float)
    tol = 1e-9 + 0.5 / max(trial.rate, 1e-9)
    window = (t >= times[0] - tol) & (t <= times[-1] + tol)
    P = trial.positions[window]
    seen = np.isfinite(P).all(axis=2).any(axis=0) if len(P) else np.zeros(trial.n_markers, bool)
    never = [lab for lab, s, w in zip(trial.labels, seen, model.markers.weight) if not s and w > 0]
    if never:
        _warn(f"{trial.source}: marker(s) {', '.join(repr(n) for n in never)} never visible in the analysis window "
              f"[{times[0]:g}, {times[-1]:g}] s")
    if not len(P):
        return
    first = P[0]
    ok = np.isfinite(first).all(axis=1)
    if ok.sum() < 2:
        return
    state = model.initial_state()
    M = model.markers.positions(state)
    M, X = M[ok], first[ok]
    s_model, c_model = _spread(M)
    s_trial, c_trial = _spread(X)
    with np.errstate(over="ignore", invalid="ignore"):
        gap = float(np.linalg.norm(c_trial - c_model))
    ratio = s_trial / s_model if s_model > 0 else np.nan
    if s_model > 0 and s_trial > 0 and not (1 / 30 < ratio < 30):
        # the nearest power of ten; a ratio beyond a double's range (1e200 mm) has none
        exponent = round(float(np.log10(ratio))) if np.isfinite(ratio) and 0 < ratio else None
        factor = f"a factor {10.0 ** exponent:g}" if exponent is not None and abs(exponent) <= 300 else "no unit factor"
        _warn(f"{trial.source}: at the first frame (t = {times[0]:g} s) the markers spread {s_trial:.4g} m around "
              f"their centroid, {ratio:.3g}x the model's markers ({s_model:.4g} m): likely the wrong units "
              f"({factor}; check {_units_field(trial.source)})")
    elif gap > max(FAR_FROM_MODEL, 20 * s_model):
        _warn(f"{trial.source}: at the first frame (t = {times[0]:g} s) the markers' centroid is {gap:.3g} m from "
              "the model's markers at the reference pose; check the units and the lab frame")


def _spread(points):
    """(RMS distance (m) of ``points`` (n, 3) m from their centroid, the centroid (3,) m),
    computed scaled so that coordinates up to a double's limit give a finite spread (inf
    only when the spread itself is beyond it), without overflow warnings."""
    points = np.asarray(points, float)
    scale = float(np.max(np.abs(points))) if points.size else 0.0
    if not (np.isfinite(scale) and scale > 0):
        return (0.0 if scale == 0 else float("inf")), np.zeros(3)
    unit = points / scale
    centroid = unit.mean(0)
    with np.errstate(over="ignore"):
        return float(np.sqrt(np.mean(np.sum((unit - centroid) ** 2, axis=1))) * scale), centroid * scale


def _units_field(source):
    """Where a trial file declares its marker units: TRC line 3 (Units), C3D POINT:UNITS."""
    return "Units on line 3" if str(source).lower().endswith(".trc") else "POINT:UNITS"


# -- run results ------------------------------------------------------------------------

def pulling_contacts(model, kin, dyn, threshold=-0.2):
    """Per contact that pulled in some frame: (name, frames pulling, lowest cosine).

    A contact force pushes each body toward its own inside: the force on the vertex body
    a, F_a, points from the centre of pressure toward a's centre of mass, and −F_a
    toward b's (the ground, whose origin is not inside anything, is skipped). A frame
    pulls when the cosine of that angle is below ``threshold`` for every side checked;
    inverted normals give cosines near −1. ``dyn`` holds the per-contact force and
    centre-of-pressure columns, ``kin`` the poses of the same frames."""
    contacts = model.contacts
    cols = getattr(dyn, "extra", {}).get("columns", {}) if dyn is not None else {}
    out = []
    if not contacts or not cols:
        return out
    state = model.initial_state()
    for c in contacts:
        keys = [f"{c.name}.F{a}_N" for a in "xyz"] + [f"{c.name}.cop_{a}_m" for a in "xyz"]
        if not all(k in cols for k in keys):
            continue
        X = np.stack([np.asarray(cols[k], dtype=float) for k in keys], axis=1)
        sides = [(body, sign) for body, sign in ((c.body_a, 1.0), (c.body_b, -1.0)) if body != 0]
        n_pull, worst = 0, 1.0
        for k in np.flatnonzero(np.isfinite(X).all(axis=1) & (np.abs(X[:, :3]).sum(axis=1) > 0)):
            if k >= len(kin.q) or not np.all(np.isfinite(kin.q[k])) or not sides:
                continue
            state.set_q(kin.q[k])
            F, cop = X[k, :3], X[k, 3:]
            cosines = []
            for body, sign in sides:
                d = state.p_WB[body] - cop
                cosines.append(float(sign * F @ d / max(np.linalg.norm(F) * np.linalg.norm(d), 1e-300)))
            if max(cosines) < threshold:
                n_pull += 1
                worst = min(worst, max(cosines))
        if n_pull:
            out.append((c.name, n_pull, worst))
    return out


def outlier_markers(kin):
    """[(name, RMS m, median RMS m)] of the tracked markers (weight > 0) whose RMS
    residual over the run's frames is above OUTLIER_FACTOR × the median over the tracked
    markers and above OUTLIER_MIN. ``kin``: a KinematicsResult with marker residuals
    (nf, n_markers, 3) m (NaN where not visible) and its marker weights."""
    res, weights = kin.marker_residual, kin.marker_weights
    if weights is None or res.ndim != 3 or res.shape[1] != len(weights):
        return []
    squared = np.sum(res**2, axis=2)
    seen = np.isfinite(squared).any(axis=0) & (np.asarray(weights) > 0)
    if seen.sum() < 3:
        return []
    with np.errstate(invalid="ignore"):
        rms = np.sqrt(np.nanmean(squared[:, seen], axis=0))
    median = float(np.median(rms))
    names = np.asarray(kin.marker_names)[seen]
    return [(str(n), float(r), median) for n, r in zip(names, rms)
            if r > max(OUTLIER_FACTOR * median, OUTLIER_MIN)]


def warn_outlier_markers(kin):
    """One warning per run naming the tracked markers of :func:`outlier_markers`."""
    found = outlier_markers(kin)
    if found:
        listed = ", ".join(f"{n} {1e3 * r:.0f} mm" for n, r, _ in found)
        _warn(f"tracked marker(s) far off their model markers over the run: {listed} (RMS residual; the tracked "
              f"markers' median {1e3 * found[0][2]:.0f} mm): mislabelled, or placed elsewhere on the model? They "
              "pull the fit; their residuals are in kinematics.csv (weight 0 in an IK task file leaves one out)")


def warn_pulling_contacts(model, kin, dyn):
    """One warning per run for the contacts that pulled (see :func:`pulling_contacts`)."""
    for name, n, worst in pulling_contacts(model, kin, dyn):
        _warn(f"contacts.{name}: the contact force pulls the surfaces together in {n} of {len(kin.time)} frames "
              f"(it points away from the bodies' insides, cosine down to {worst:.2f}); inverted normals? see the "
              "reference-pose normal check")
