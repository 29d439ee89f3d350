"""The Newton step with the contacts exact: nonlinear elimination of the elastic-foundation
contacts from the FDK residual's linear model.

Newton's step −J⁻¹ f (paper Fig. 1) trusts the linear model f + J Δα of the whole residual.
On an implant knee that model fails over a single step, and almost all of its error is the
contacts': measured on the DM knee in gait (og1 2.6 s, a warm frame 184 N from its root),
f^FDK along the Newton step departs from f + J Δα by 10.1 N; with the contacts' generalised
forces replaced by their linearisation Q_c + K_c dq̂/dα Δα it departs by 0.108 N, with the
ligaments' by 10.1 N again. The marker tracking, the wrapped paths and the recruitment
(Eq. 11) are linear to 1 % of that over the step; the contact, an elastic foundation whose
patch grows and whose vertices enter and leave it, is not.

So the step solves, instead of the linear model, the model in which the contacts are
exact and everything else linear (nonlinear elimination: Lanzkron, Rose & Wilkes, SIAM J.
Sci. Comput. 17, 1996; Cai & Keyes, SIAM J. Sci. Comput. 24, 2002):

    g(Δα) = f + J_s Δα − R [Q_c(q̂ ⊕ U Δα) − Q_c(q̂)] = 0,

* U = dq̂/dα (n, n_fdk), the kinematic sensitivity of the analytic Jacobian
  (:func:`openfdk.fdk.jacobian.kinematic_sensitivity`): the contact bodies' poses move
  with α as the marker tracking (Eqs. 4–5) or the constraints (Eqs. 1–3) move them;
* R (n_fdk, n_c): how f^FDK answers a change of the applied loads on the contact bodies'
  coordinates, ∂f^FDK/∂Q_c = −R, the recruitment's sensitivity at its active set
  (:func:`openfdk.recruitment.recruitment_sensitivity` with dd = −ΔQ, Eq. 13 puts the
  applied loads in d);
* Q_c (n_c,) the contacts' generalised forces on those coordinates, K_c = ∂Q_c/∂q̂ their
  stiffness (exact in grid mode, :mod:`openfdk.contact.elastic_foundation`);
* J_s = J + R K_c U, the Jacobian of everything but the contacts; J = J_s − R K_c U at
  any pose.

g is solved by Newton's method with g' = J_s − R K_c(q̂ ⊕ UΔα) U: each iteration is one
evaluation of the contacts (about 0.4 ms with K on DM's two implant pairs) where a residual
evaluation is a marker tracking, every path, the recruitment (about 10 ms). Broyden's
update (fdk/newton.py) corrects J_s by what the model missed, f(α + Δα) − g(Δα), so the
contacts are never linearised beyond one step.

Where the contacts are not what bends f^FDK (the bench's own knee: its wrapped ligament
strands), g misses about as much as the linear model does, and its contact evaluations
are spent for nothing: :meth:`ContactSplit.pays` measures that on the large steps and
puts the split to sleep for SLEEP_FRAMES frames (docs/fdk.md, "The step with the contacts
exact").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..contact.limits import quiet_depth
from ..kinematics.frame_kernels import small_solve
from ..recruitment import RecruitmentSensitivity

#: Newton iterations on g per FDK step at most
INNER_ITERATIONS = 8
#: halvings of an inner step that did not reduce max |g|
INNER_HALVINGS = 4
#: the step is taken from g only when g was brought below this fraction of max |f^FDK|
#: (else the inner Newton did not converge: the linear model's step is taken)
INNER_SOLVED = 0.1
#: g is solved only where the linear model's step is at most this many trust radii long
#: (a cold frame's steps are cut by the region, and the contacts-exact step would be too)
INNER_REACH = 2.0
#: the split's gain is measured on steps where the linear model missed f^FDK by more than
#: this many tolerances and this fraction of |f| at the step's start (near the root both
#: models miss by J's own error and the measure says nothing) ...
GAIN_FLOOR = 100.0
GAIN_RELATIVE = 0.01
#: ... and where g and the linear model differ by more than this fraction of that miss
GAIN_SIGNAL = 0.1
#: where g missed f^FDK by more than this fraction of the linear model's miss, the contacts
#: are not what bends f^FDK (the bench's own knee: its wrapped ligaments) and the split
#: sleeps for SLEEP_FRAMES frames: the linear model's steps, no contact evaluations
GAIN_LIMIT = 0.7
#: ... as a running mean (the newest ratio's weight): measured on the six DM trials, 5–10 %
#: of the ratios exceed 0.5 (up to 5), one at a time among ratios of 0.01–0.3; on the
#: bench's own knee most are 0.6–1.2
GAIN_WEIGHT = 0.25
#: ... and starting from this where nothing was measured yet (the first ratio above 0.7
#: puts it to sleep: the bench's own knee's first ratios are 0.97)
GAIN_PRIOR = 0.7
SLEEP_FRAMES = 10
#: g is solved to this fraction of max |f^FDK| at the step's start (the linear parts' own
#: error over the step is about 1e-3 of it on DM), or to a tenth of the FDK tolerance
INNER_RELATIVE = 1e-3


@dataclass
class ContactSplit:
    """The contacts' part of the FDK residual's model at a frame (module docstring).

    U (n, n_fdk) dq̂/dα [m or rad per DOF unit]; R (n_fdk, n_c) −∂f^FDK/∂Q_c (zero columns
    for coordinates outside the equilibrium rows); cols (n_c,) the q̂ indices of the contact
    bodies' coordinates; blocks (n_contacts, 2): where each contact's bodies a and b start
    in cols (−1: a fixed body); J_s (n_fdk, n_fdk) or None: the Jacobian of everything but
    the contacts once a pose has split J; J_whole (n_fdk, n_fdk) or None: the whole J at
    the last step's start, Broyden-updated along it (as without the split: the next
    frame's fallback, fdk/newton.py). Arrays only (a checkpoint carries it between
    frames); the methods take the model's ContactForces ``contacts``."""

    U: np.ndarray
    R: np.ndarray
    cols: np.ndarray
    blocks: np.ndarray
    J_s: np.ndarray = None
    J_whole: np.ndarray = None
    gain: float = float("nan")
    sleep: int = 0

    def pays(self, f0, f, f_linear, f_model, tolerance):
        """Whether the split pays (None: no measure): after a step from f^FDK = f0 to f
        (n_fdk,), the ratio of g's miss |f − f_model| to the linear model's |f − f_linear|
        (2-norms), measured where the linear model missed by more than GAIN_FLOOR
        tolerances and GAIN_RELATIVE of |f0| (a step near the root misses by J's own error,
        which g shares) and the two models differ by more than GAIN_SIGNAL of that miss
        (else the contacts did not bend the step). ``gain``: the ratios' running mean, each
        ratio capped at 1 (g worse than the linear model: no gain), the newest weighted
        GAIN_WEIGHT, from GAIN_PRIOR when none was measured. Where it exceeds GAIN_LIMIT,
        the split sleeps SLEEP_FRAMES frames (``sleep``)."""
        linear_miss = float(np.linalg.norm(f - f_linear))
        if not (linear_miss > max(GAIN_FLOOR * tolerance, GAIN_RELATIVE * float(np.linalg.norm(f0)))
                and float(np.linalg.norm(f_model - f_linear)) > GAIN_SIGNAL * linear_miss):
            return None
        ratio = min(float(np.linalg.norm(f - f_model)) / linear_miss, 1.0)  # worse than linear: no gain
        self.gain = (1.0 - GAIN_WEIGHT) * (GAIN_PRIOR if np.isnan(self.gain) else self.gain) + GAIN_WEIGHT * ratio
        if self.gain <= GAIN_LIMIT:
            return True
        self.sleep = SLEEP_FRAMES
        return False

    def copy(self):
        return replace(self, J_s=None if self.J_s is None else self.J_s.copy(),
                       J_whole=None if self.J_whole is None else self.J_whole.copy())

    def terms(self, contacts, state):
        """(Q_c (n_c,) N or N m, K_c U (n_c, n_fdk)) of the ``contacts`` at ``state``: each
        contact's 12 generalised forces and its (12, 12) stiffness placed at its bodies'
        blocks of cols (:class:`~openfdk.contact.element.ContactElement`)."""
        Q = np.zeros(len(self.cols))
        KU = np.zeros((len(self.cols), self.U.shape[1]))
        U_c = self.U[self.cols]
        for contact, starts in zip(contacts.contacts, self.blocks):
            # the model's poses q̂ ⊕ U Δα are predictions, not poses of the model (the
            # tracking is not solved there): a depth near max_depth there says nothing of
            # the results (DM knee: 10 mm in the inner Newton of a lead-in frame, never
            # past 0.7 mm in a residual evaluation of the six trials), so it does not warn
            with quiet_depth():
                res = contact.evaluate(state, True)
            for i, c in enumerate(starts):
                if c < 0:
                    continue
                Q[c:c + 6] += res.Q[6 * i:6 * i + 6]
                for m, d in enumerate(starts):
                    if d >= 0:
                        KU[c:c + 6] += res.K[6 * i:6 * i + 6, 6 * m:6 * m + 6] @ U_c[d:d + 6]
        return Q, KU

    def jacobian_at(self, KU):
        """J (n_fdk, n_fdk) at a pose whose contact stiffness along U is ``KU``."""
        return self.J_s - self.R @ KU

    def split(self, J, KU):
        """Take J (n_fdk, n_fdk), the whole residual's Jacobian at a pose with contact terms
        ``KU``, as the linear model: J_s = J + R K_c U."""
        self.J_s = J + self.R @ KU

    def model(self, contacts, f, state, Q0, step):
        """g(step) (n_fdk,) and the contacts' K_c U there: the model at ``step`` (n_fdk,)
        from the pose ``state`` with residual f and contact forces Q0 (module docstring)."""
        moved = state.copy()
        moved.displace(self.U @ step)
        Q, KU = self.terms(contacts, moved)
        return f + self.J_s @ step - self.R @ (Q - Q0), KU

    def solve(self, contacts, f, state, Q0, step, tolerance, box=None):
        """(Δα (n_fdk,), g(Δα)): Newton on g = 0 from ``step`` (the linear model's step),
        within the trust region |Δα_i| ≤ box_i (``box`` (n_fdk,) SI, or None: no bound; a
        Newton step that would leave it is cut at its boundary), at most
        :data:`INNER_ITERATIONS` contact evaluations, an iteration that does not reduce
        max |g| halved up to :data:`INNER_HALVINGS` times; the best iterate when g is not
        solved to ``tolerance`` (N, N m)."""
        g, KU = self.model(contacts, f, state, Q0, step)
        best, g_best = step, g
        evaluations = 1
        while evaluations < INNER_ITERATIONS and np.max(np.abs(g_best)) > tolerance:
            try:
                d = small_solve(self.jacobian_at(KU), -g_best)
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(d)):
                break
            if box is not None:
                d = d * _fraction_inside(best, d, box)
                if not np.any(d):
                    break  # at the region's boundary, pointing out
            for _ in range(INNER_HALVINGS + 1):
                g, KU_new = self.model(contacts, f, state, Q0, best + d)
                evaluations += 1
                if np.max(np.abs(g)) < np.max(np.abs(g_best)):
                    break
                d = 0.5 * d
            else:
                break
            best, g_best, KU = best + d, g, KU_new
        return best, g_best


def _fraction_inside(x, d, box):
    """The largest τ ∈ [0, 1] with |x + τ d| ≤ box componentwise (x inside the box)."""
    tau = 1.0
    for xi, di, bi in zip(x, d, box):
        if di > 0.0:
            tau = min(tau, (bi - xi) / di)
        elif di < 0.0:
            tau = min(tau, (-bi - xi) / di)
    return max(tau, 0.0)


def contact_columns(contacts, column):
    """(cols (n_c,), blocks (n_contacts, 2)) of a ContactSplit: the q̂ indices of the
    contact bodies' coordinates (6 per moving body, in body order) and where each
    contact's bodies a and b start in cols (−1: a fixed body). contacts : the model's
    ContactForces; column (n_bodies,) : the bodies' first q̂ column (−1: fixed)."""
    bodies = sorted({b for e in contacts.contacts for b in (e.body_a, e.body_b) if column[b] >= 0})
    cols = np.array([column[b] + i for b in bodies for i in range(6)], dtype=np.int64)
    blocks = np.array([[6 * bodies.index(b) if column[b] >= 0 else -1 for b in (e.body_a, e.body_b)]
                       for e in contacts.contacts], dtype=np.int64).reshape(-1, 2)
    return cols, blocks


def checked_split(split, contacts, reference, n_fdk):
    """A checkpoint's ContactSplit ``split`` (untrusted) checked against the model:
    ``cols`` and ``blocks`` those of :func:`contact_columns` for the model's initial
    state ``reference`` (they index the kernels' arrays), U (n, n_fdk), R (n_fdk, n_c),
    J_s and J_whole (n_fdk, n_fdk) or None; ValueError otherwise."""
    from ..trial import restored

    if contacts is None:
        raise ValueError("FDK Jacobian: a contacts' split, and the model has no contacts")
    cols, blocks = contact_columns(contacts, reference.column)
    if not (isinstance(split.cols, np.ndarray) and isinstance(split.blocks, np.ndarray)
            and np.array_equal(split.cols, cols) and np.array_equal(split.blocks, blocks)):
        raise ValueError("FDK Jacobian: the contacts' split names other coordinates than the model's")
    restored.array(split.U, (reference.n_coords, n_fdk), "FDK Jacobian: U")
    restored.array(split.R, (n_fdk, len(cols)), "FDK Jacobian: R")
    restored.optional(split.J_s, (n_fdk, n_fdk), "FDK Jacobian: J_s")
    restored.optional(split.J_whole, (n_fdk, n_fdk), "FDK Jacobian: J_whole")
    if not isinstance(split.gain, (int, float, np.floating)) or isinstance(split.gain, bool):
        raise ValueError("FDK Jacobian: gain: expected a number")
    if not isinstance(split.sleep, (int, np.integer)) or isinstance(split.sleep, bool):
        raise ValueError("FDK Jacobian: sleep: expected a whole number")
    return split


def contact_split(ctx, ev, U, p, sensitivity=None):
    """The ContactSplit (without J_s) at an evaluation's pose, or None when the model has
    no contacts or their K is not exact (exact mode: the curvature of B is left out).

    ctx : FDKContext; ev : the Evaluation (its state's body columns, its FrameForces' C,
    d, s and recruitment result); U (n, n_fdk) dq̂/dα; p : the recruitment's power;
    sensitivity : the RecruitmentSensitivity of ev's recruitment if already factored (the
    analytic Jacobian's), else factored here."""
    contacts = ctx.solver.forces.by_kind.get("contacts")
    if contacts is None or not contacts.exact_stiffness:
        return None
    fr = ev.frame
    cols, blocks = contact_columns(contacts, ev.state.column)
    rows = np.asarray(ctx.solver.layout.eq_coords)
    where = {int(c): i for i, c in enumerate(rows)}
    inside = [j for j, c in enumerate(cols) if int(c) in where]
    R = np.zeros((len(ctx.fdk_columns), len(cols)))
    if inside:
        dd = np.zeros((len(inside), len(rows)))
        dd[np.arange(len(inside)), [where[int(cols[j])] for j in inside]] = 1.0
        if sensitivity is None:
            sensitivity = RecruitmentSensitivity(fr.recruitment, fr.C, fr.d, fr.s, p)
        df = sensitivity.along(None, dd)
        # ΔQ on a row enters d as −ΔQ (Eq. 13): ∂f^FDK/∂Q_c = −df/dd
        R[:, inside] = df[:, ctx.fdk_columns].T
    return ContactSplit(U, R, cols, blocks)


__all__ = ["ContactSplit", "contact_split", "contact_columns", "checked_split", "GAIN_FLOOR", "GAIN_RELATIVE", "GAIN_SIGNAL", "GAIN_LIMIT", "GAIN_WEIGHT", "GAIN_PRIOR",
           "SLEEP_FRAMES", "INNER_REACH", "INNER_ITERATIONS", "INNER_HALVINGS", "INNER_RELATIVE", "INNER_SOLVED"]
