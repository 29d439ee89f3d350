"""The virtual subject's TRUE joint and the contact-consistent mandible pose.

The model sees the subject folder (segmented bone surfaces, a uniform 1 mm cartilage
offset, registered brace markers). The truth differs from it, as in a real study
(:class:`TruthOptions`):

(a) the articular disc and cartilage have a varying thickness instead of the model's
    uniform layer,
(b) the true bone surfaces differ from the segmented ones by a smooth random field,
(c) the true brace marker positions differ from the registered ones by a small rigid
    transformation (applied by :mod:`openfdk.mandible.experiment`).

With every difference zero, the truth is exactly the model's view.

Contact condition (true joint): on each side, the true condyle surface offset along
its normal by the local layer thickness touches the true fossa surface, without
penetration. The fossa is a height field Z(x, y) (normals down), so for the offset
condyle points P(s) (skull frame) the vertical gap

    g(s) = Z(P_x(s), P_y(s)) − P_z(s)

is positive exactly where a point is below the fossa (in the joint space), zero on it,
and the surfaces touch without penetration iff  min_s g(s) = 0  (:func:`min_gap`).

Pose of the mandible anatomical frame M in the skull frame S:
R_SM = Rz(yaw) Ry(opening) Rx(roll), origin p_SM = (x, y, z). A task prescribes
(x, y, yaw, opening); :func:`solve_contact` finds (z, roll) such that both sides touch.
The gap of a side is m(roll) − z, so this is one scalar root per frame,
m_r(roll) = m_l(roll), solved by safeguarded Newton with the envelope-theorem
derivative ∂m/∂roll = (∇Z, −1)·R_SM (e_x × p_M*) at the minimiser p_M*.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .geometry import SmoothField

__all__ = [
    "SIDES",
    "ContactSolution",
    "TrueJoint",
    "TruthOptions",
    "min_gap",
    "relative_rotation",
    "solve_contact",
]

SIDES = ("r", "l")
_MM = 1e-3


@dataclass(frozen=True)
class TruthOptions:
    """How the virtual subject's true joint differs from the subject folder (model).

    All lengths in mm, angles in deg (user-facing). Every field is a *difference*;
    :meth:`exact` (all zero) makes the truth equal the model's view.

    (a) Disc + cartilage layer. The model offsets the condyles by the folder's uniform
        ``cartilage_offset`` L (1 mm, as in the paper). The true layer at a condyle
        point with outward normal n is  L + Δ(n₁),  n₁ = n·e1 (the joint's
        antero-posterior axis), the quadratic through the three excesses below at
        n₁ = +1/√2 (antero-superior), 0 (superior), −1/√2 (postero-superior):

        * ``disc_excess_anterior`` 0.3 mm → 1.3 mm true layer (intermediate zone,
          where the condyle meets the eminence),
        * ``disc_excess_superior`` 0.8 mm → 1.8 mm,
        * ``disc_excess_posterior`` 1.5 mm → 2.5 mm (posterior band).

        Chosen to span the ≈1–3 mm of the disc (thin intermediate zone, thick posterior
        band) and CBCT joint spaces (anterior ≈1.3, superior ≈2.5, posterior ≈2.1 mm,
        Ikeda & Kawamura 2009). Because the true layer differs from L, the true closed
        pose sits slightly lower than the CT (subject-frame) pose.
    (b) ``segmentation_error_rms`` 0.2 mm: true bone = segmented bone + a smooth random
        field (normal displacement on the condyle, vertical on the fossa; 8 plane waves
        of wavelength ``segmentation_wavelength`` 10–20 mm, independent per surface).
    (c) ``registration_translation`` 0.3 mm and ``registration_rotation`` 0.1°: each
        brace's true marker positions are its registered (subject-folder) positions moved
        by a rigid transformation of this size (random direction/axis, about the brace's
        marker centroid); the markers move by 0.25–0.35 mm (0.1° at 31 mm from the
        centroid is 0.05 mm). Seen from the condyles, ≈140 mm from the braces, the
        rotation part alone is 0.25 mm: the brace measurement of the condyles is biased
        by ≈0.3–0.6 mm, as the paper's registration was.
    """

    disc_excess_anterior: float = 0.3
    disc_excess_superior: float = 0.8
    disc_excess_posterior: float = 1.5
    segmentation_error_rms: float = 0.2
    segmentation_wavelength: tuple = (10.0, 20.0)
    registration_translation: float = 0.3
    registration_rotation: float = 0.1

    @classmethod
    def exact(cls) -> TruthOptions:
        """No difference between truth and model."""
        return cls(0.0, 0.0, 0.0, 0.0, (10.0, 20.0), 0.0, 0.0)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["segmentation_wavelength"] = list(self.segmentation_wavelength)
        return d


@dataclass(frozen=True)
class TrueJoint:
    """Analytic true joint surfaces of both sides (SI units).

    ``condyles``/``fossae``: dict side → shape (the subject's generated surfaces, see
    :mod:`.geometry`); ``layer`` m, the model's uniform layer L; ``disc_excess`` (3,) m
    (anterior, superior, posterior); ``condyle_errors``/``fossa_errors``: dict side →
    :class:`SmoothField` (true − segmented; mandible frame / skull-frame planar).
    """

    condyles: dict
    fossae: dict
    layer: float
    disc_excess: np.ndarray
    condyle_errors: dict
    fossa_errors: dict

    @classmethod
    def build(cls, condyles: dict, fossae: dict, layer: float, options: TruthOptions,
              rng: np.random.Generator) -> TrueJoint:
        """The true joint for ``options``; random fields drawn from ``rng`` (right, then left)."""
        wavelengths = tuple(_MM * np.asarray(options.segmentation_wavelength, dtype=float))
        rms = _MM * options.segmentation_error_rms
        condyle_errors, fossa_errors = {}, {}
        for side in SIDES:
            condyle_errors[side] = SmoothField.random(rng, rms, wavelengths)
            fossa_errors[side] = SmoothField.random(rng, rms, wavelengths, planar=True)
        excess = _MM * np.array([options.disc_excess_anterior, options.disc_excess_superior,
                                 options.disc_excess_posterior])
        joint = cls(dict(condyles), dict(fossae), float(layer), excess, condyle_errors, fossa_errors)
        for side in SIDES:
            s = _cap_grid(condyles[side].cap_extent, 41)
            thickness = joint.layer_thickness(side, s)
            if np.min(thickness) <= 0.0:
                raise ValueError(f"TruthOptions give a non-positive true layer on the "
                                 f"{side} condyle ({1e3 * np.min(thickness):.2f} mm); "
                                 f"reduce the negative disc excesses")
        return joint

    def disc_thickness(self, side: str, s) -> np.ndarray:
        """True disc/cartilage layer L + Δ(n₁) (m) at cap parameters s (..., 2).

        Δ(n₁) = ε_s + α n₁ + β n₁², α = (ε_a − ε_p)/√2, β = ε_a + ε_p − 2 ε_s, so that
        Δ(1/√2) = ε_a, Δ(0) = ε_s, Δ(−1/√2) = ε_p.
        """
        shape = self.condyles[side]
        n1 = shape.normals(s) @ shape.axes[:, 0]
        eps_a, eps_s, eps_p = self.disc_excess
        alpha = (eps_a - eps_p) / np.sqrt(2.0)
        beta = eps_a + eps_p - 2.0 * eps_s
        return self.layer + eps_s + alpha * n1 + beta * n1 ** 2

    def layer_thickness(self, side: str, s) -> np.ndarray:
        """Offset of the true contact surface from the segmented condyle along its normal:
        disc layer + segmentation difference (m), s (..., 2) → (...)."""
        shape = self.condyles[side]
        return self.disc_thickness(side, s) + self.condyle_errors[side].value(shape.points(s))

    def offset_points(self, side: str, s) -> np.ndarray:
        """True condyle surface offset by the true layer, mandible frame:
        x(s) + (layer + error)(s) n(s); s (..., 2) → (..., 3) m."""
        shape = self.condyles[side]
        return shape.points(s) + self.layer_thickness(side, s)[..., None] * shape.normals(s)

    def fossa_height_and_gradient(self, side: str, x, y):
        """True fossa Z(x, y) + δ(x, y) and its gradient: (...) m → z, dz/dx, dz/dy."""
        z, zx, zy = self.fossae[side].height_and_gradient(x, y)
        field = self.fossa_errors[side]
        if len(field.amplitudes):
            p = np.stack([x, y, np.zeros_like(x)], axis=-1)
            g = field.gradient(p)
            z, zx, zy = z + field.value(p), zx + g[..., 0], zy + g[..., 1]
        return z, zx, zy

    def fossa_height(self, side: str, x, y):
        """True fossa height (m) at subject-frame x, y (...) m."""
        z = self.fossae[side].height(x, y)
        field = self.fossa_errors[side]
        if len(field.amplitudes):
            z = z + field.value(np.stack([x, y, np.zeros_like(x)], axis=-1))
        return z


def _cap_grid(cap_extent: float, n: int) -> np.ndarray:
    """Cap parameters on an n × n grid over [−ρ, ρ]², inside |s| ≤ ρ: (K, 2)."""
    u = np.linspace(-cap_extent, cap_extent, n)
    s = np.stack(np.meshgrid(u, u, indexing="ij"), axis=-1).reshape(-1, 2)
    return s[np.hypot(s[:, 0], s[:, 1]) <= cap_extent + 1e-12]


def relative_rotation(yaw, opening, roll) -> np.ndarray:
    """R_SM = Rz(yaw) Ry(opening) Rx(roll); angles (n,) rad → (n, 3, 3).

    Opening (positive) lowers the chin: Ry(φ) takes x toward −z.
    """
    yaw, opening, roll = (np.atleast_1d(np.asarray(a, dtype=float)) for a in (yaw, opening, roll))
    cz, sz, cy, sy, cx, sx = np.cos(yaw), np.sin(yaw), np.cos(opening), np.sin(opening), np.cos(roll), np.sin(roll)
    R = np.empty(yaw.shape + (3, 3))
    R[..., 0, 0] = cz * cy
    R[..., 0, 1] = cz * sy * sx - sz * cx
    R[..., 0, 2] = cz * sy * cx + sz * sx
    R[..., 1, 0] = sz * cy
    R[..., 1, 1] = sz * sy * sx + cz * cx
    R[..., 1, 2] = sz * sy * cx - cz * sx
    R[..., 2, 0] = -sy
    R[..., 2, 1] = cy * sx
    R[..., 2, 2] = cy * cx
    return R


class _SideCache:
    """Square grid of cap parameters (n × n over [−ρ, ρ]², the points outside |s| ≤ ρ
    masked) and their offset points, for the global search of one side."""

    def __init__(self, joint: TrueJoint, side: str, n_grid: int = 21):
        self.side = side
        self.n = n_grid
        self.cap_extent = joint.condyles[side].cap_extent
        u = np.linspace(-self.cap_extent, self.cap_extent, n_grid)
        self.s = np.stack(np.meshgrid(u, u, indexing="ij"), axis=-1).reshape(-1, 2)
        self.inside = np.hypot(self.s[:, 0], self.s[:, 1]) <= self.cap_extent + 1e-12
        self.p_M = joint.offset_points(side, np.where(self.inside[:, None], self.s, 0.0))
        self.spacing = 2.0 * self.cap_extent / (n_grid - 1)


def _gap(joint, side, s, R_SM, p_SM):
    """Vertical gap g (B,), offset point p_M (B, 3) and P_S (B, 3) for s (B, 2)."""
    p_M = joint.offset_points(side, s)
    P = p_SM + np.einsum("bij,bj->bi", R_SM, p_M)
    return joint.fossa_height(side, P[:, 0], P[:, 1]) - P[:, 2], p_M, P


def min_gap(joint: TrueJoint, side: str, R_SM, p_SM, cache: _SideCache | None = None,
            fd_step: float = 1e-4, iterations: int = 6, s_start=None, candidates: int = 3):
    """min_s g(s) of one side for a batch of mandible poses.

    Args: R_SM (B, 3, 3), p_SM (B, 3) m — mandible pose in the skull frame; s_start
    (B, 2) optional start of the local search (skips the global grid search).
    Returns: gap (B,) m, s* (B, 2), p_M* (B, 3) m (offset condyle point, mandible frame),
    P* (B, 3) m (the same point, skull frame).

    A global search on a parameter grid (unless ``s_start``), then Newton on s with a
    6-point finite-difference gradient and Hessian (step ``fd_step`` in s),
    started from the ``candidates`` lowest local minima of the grid.
    """
    cache = cache or _SideCache(joint, side)
    R_SM, p_SM = np.asarray(R_SM, dtype=float), np.asarray(p_SM, dtype=float)
    B = len(p_SM)
    if s_start is None:
        # global search: the `candidates` lowest local minima of the grid values are
        # each refined, and the lowest result is kept (two parts of the surface can
        # come equally close; refining only the lowest grid point could pick the wrong one)
        P = p_SM[:, None, :] + np.einsum("bij,kj->bki", R_SM, cache.p_M[cache.inside])
        g = np.full((B, cache.n * cache.n), np.inf)
        g[:, cache.inside] = joint.fossa_height(side, P[..., 0], P[..., 1]) - P[..., 2]
        g = g.reshape(B, cache.n, cache.n)
        padded = np.pad(g, ((0, 0), (1, 1), (1, 1)), constant_values=np.inf)
        local = np.ones_like(g, dtype=bool)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                if di or dj:
                    local &= g <= padded[:, 1 + di:1 + di + cache.n, 1 + dj:1 + dj + cache.n]
        ranked = np.where(local & np.isfinite(g), g, np.inf).reshape(B, -1)
        k = min(candidates, ranked.shape[1])
        best = np.argsort(ranked, axis=1)[:, :k]                                # (B, k)
        best = np.where(np.isfinite(np.take_along_axis(ranked, best, 1)), best, best[:, :1])
        gap, s, p_M, P = min_gap(joint, side, np.repeat(R_SM, k, axis=0), np.repeat(p_SM, k, axis=0),
                                 cache, fd_step, iterations, s_start=cache.s[best.reshape(-1)])
        pick = np.argmin(gap.reshape(B, k), axis=1) + k * np.arange(B)
        return gap[pick], s[pick], p_M[pick], P[pick]
    s = np.array(s_start, dtype=float)
    h = fd_step
    offsets = np.array([[0, 0], [h, 0], [-h, 0], [0, h], [0, -h], [h, h]])
    for _ in range(iterations):
        stencil = (s[:, None, :] + offsets[None]).reshape(-1, 2)
        f = _gap(joint, side, stencil, np.repeat(R_SM, 6, axis=0), np.repeat(p_SM, 6, axis=0))[0]
        f = f.reshape(B, 6)
        # central differences for the gradient (its zero is the minimiser) and the
        # diagonal of the Hessian; forward difference for the mixed term
        grad = np.stack([(f[:, 1] - f[:, 2]) / (2 * h), (f[:, 3] - f[:, 4]) / (2 * h)], axis=1)
        H = np.empty((B, 2, 2))
        H[:, 0, 0] = (f[:, 1] - 2 * f[:, 0] + f[:, 2]) / h ** 2
        H[:, 1, 1] = (f[:, 3] - 2 * f[:, 0] + f[:, 4]) / h ** 2
        H[:, 0, 1] = H[:, 1, 0] = (f[:, 5] - f[:, 1] - f[:, 3] + f[:, 0]) / (h * h)
        det = H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] ** 2
        convex = (det > 0) & (H[:, 0, 0] > 0)
        step = np.where(convex[:, None],
                        -np.linalg.solve(np.where(convex[:, None, None], H, np.eye(2)), grad[..., None])[..., 0],
                        -grad * (cache.spacing / np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), 1e-300)))
        # a Newton step never leaves the grid cell of the search by more than one spacing
        norm = np.linalg.norm(step, axis=1, keepdims=True)
        step *= np.minimum(1.0, cache.spacing / np.maximum(norm, 1e-300))
        s = s + step
        radius = np.linalg.norm(s, axis=1, keepdims=True)
        s = np.where(radius > cache.cap_extent, s * cache.cap_extent / radius, s)
        if np.max(np.abs(step)) < 1e-10:
            break
    gap, p_M, P = _gap(joint, side, s, R_SM, p_SM)
    return gap, s, p_M, P


@dataclass(frozen=True)
class ContactSolution:
    """Result of :func:`solve_contact` for n frames (SI units).

    ``z`` (n,) m and ``roll`` (n,) rad: the solved DOFs; ``R_SM`` (n, 3, 3), ``p_SM``
    (n, 3) m: the mandible pose in the skull frame; ``gap`` (n, 2) m: residual min gap
    (right, left); ``cap_parameters`` (n, 2, 2); ``contact_S`` (n, 2, 3) m: contact
    points (skull frame); ``iterations``: iterations of the slowest frame.
    """

    z: np.ndarray
    roll: np.ndarray
    R_SM: np.ndarray
    p_SM: np.ndarray
    gap: np.ndarray
    cap_parameters: np.ndarray
    contact_S: np.ndarray
    iterations: int


def _height_function(joint: TrueJoint, side: str, R_SM, x, y, cache, s_start=None):
    """m(roll) = min_s g(s) at z = 0 and its derivative ∂m/∂roll (envelope theorem).

    Because P_x, P_y do not depend on z and ∂P_z/∂z = 1, the gap at any z is m − z.
    Returns m (B,), dm/droll (B,), s* (B, 2), P* (B, 3) m at z = 0.
    """
    p = np.column_stack([x, y, np.zeros_like(x)])
    m, s, p_M, P = min_gap(joint, side, R_SM, p, cache, s_start=s_start)
    _, zx, zy = joint.fossa_height_and_gradient(side, P[:, 0], P[:, 1])
    # ∂P/∂roll = R_SM (e_x × p_M)  (R = Rz Ry Rx, d Rx/d roll = Rx [e_x]×)
    dP = np.einsum("bij,bj->bi", R_SM, np.cross(np.array([1.0, 0.0, 0.0]), p_M))
    return m, zx * dP[:, 0] + zy * dP[:, 1] - dP[:, 2], s, P


def solve_contact(joint: TrueJoint, x, y, yaw, opening, *, tolerance: float = 1e-10,
                  max_iterations: int = 80, roll_bracket: float = 0.2) -> ContactSolution:
    """Solve (z, roll) so both offset condyles touch their fossae, frame by frame.

    The gap of side k at (z, roll) is m_k(roll) − z (P_x, P_y do not depend on z), so
    both sides touch iff h(roll) = m_r(roll) − m_l(roll) = 0 and z = m_r(roll). h is
    continuous (a minimum of smooth functions; it has kinks where the contact jumps
    between two parts of the surface) and increases with roll (positive roll lowers the
    right condyle). It is solved by safeguarded Newton: a Newton step with the envelope
    derivative when it stays inside the bracket [lo, hi] (h(lo) < 0 < h(hi), initially
    ± ``roll_bracket`` rad) and at least halves |h|, a bisection step otherwise.

    Args: x, y (n,) m — mandible origin (midpoint of the condyle tops) in the skull
    frame; yaw, opening (n,) rad. Returns a :class:`ContactSolution` (|gap| <
    ``tolerance`` m on both sides).
    Raises ValueError when a frame does not converge or a contact point lies on the
    rim of the meshed condyle cap (the motion would leave the modelled surface).
    """
    x, y, yaw, opening = (np.atleast_1d(np.asarray(a, dtype=float)) for a in (x, y, yaw, opening))
    n = len(x)
    caches = {side: _SideCache(joint, side) for side in SIDES}
    roll = np.zeros(n)
    lo, hi = np.full(n, -roll_bracket), np.full(n, roll_bracket)
    h_previous = np.full(n, np.inf)
    m, s_all, contact = np.zeros((n, 2)), np.zeros((n, 2, 2)), np.zeros((n, 2, 3))
    # global grid search in the first evaluation of every frame and to verify a
    # converged frame; local searches from the previous minimiser in between. A frame
    # whose verification finds another, lower minimum restarts with global searches only.
    active = np.arange(n)
    search_global = np.ones(n, dtype=bool)
    always_global = np.zeros(n, dtype=bool)
    iteration = 0
    while len(active):
        iteration += 1
        if iteration > max_iterations:
            residual = np.abs(m[active, 0] - m[active, 1])[:5]
            raise ValueError(f"contact solve did not converge at frames {active[:5].tolist()}: "
                             f"|m_r − m_l| = {residual} m after {max_iterations} iterations")
        dm = np.zeros((n, 2))
        for group in (active[search_global[active]], active[~search_global[active]]):
            if not len(group):
                continue
            R = relative_rotation(yaw[group], opening[group], roll[group])
            for k, side in enumerate(SIDES):
                start_s = None if search_global[group[0]] else s_all[group, k]
                m[group, k], dm[group, k], s_all[group, k], contact[group, k] = _height_function(
                    joint, side, R, x[group], y[group], caches[side], start_s)
        a = active
        h, dh = m[a, 0] - m[a, 1], dm[a, 0] - dm[a, 1]
        done = np.abs(h) < tolerance
        finished = done & search_global[a]
        verify = done & ~search_global[a]
        # a failed verification: the local searches missed a lower minimum
        failed = search_global[a] & ~always_global[a] & (iteration > 1) & ~done
        restart = a[failed]
        always_global[restart] = True
        lo[restart], hi[restart], h_previous[restart] = -roll_bracket, roll_bracket, np.inf
        lo[a] = np.where(h < 0, roll[a], lo[a])
        hi[a] = np.where(h > 0, roll[a], hi[a])
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = roll[a] - h / dh
        accept = (dh > 0) & (newton > lo[a]) & (newton < hi[a]) & (np.abs(h) < 0.5 * h_previous[a])
        roll[a] = np.where(done, roll[a], np.where(accept, newton, 0.5 * (lo[a] + hi[a])))
        h_previous[a] = np.abs(h)
        search_global[a] = verify | always_global[a]
        active = a[~finished]
    z = m[:, 0].copy()                                         # z = m_r(roll): right gap 0
    contact[..., 2] += z[:, None]
    gap = m - z[:, None]
    for k, side in enumerate(SIDES):
        rim = np.linalg.norm(s_all[:, k], axis=1) > caches[side].cap_extent - 1e-6
        if np.any(rim):
            raise ValueError(f"contact on the {side} condyle reached the rim of the meshed cap "
                             f"at frame {int(np.argmax(rim))}: the motion leaves the modelled "
                             f"articular surface")
    R = relative_rotation(yaw, opening, roll)
    return ContactSolution(z=z, roll=roll, R_SM=R, p_SM=np.column_stack([x, y, z]), gap=gap,
                           cap_parameters=s_all, contact_S=contact, iterations=iteration)
