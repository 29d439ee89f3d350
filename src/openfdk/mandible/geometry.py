"""Procedural temporomandibular-joint surfaces: analytic shapes and their meshes.

The virtual subject's TMJ surfaces are smooth functions; the STL files of a subject
folder are meshes of them (docs/design.md §2; the numbers are in
``openfdk/data/mandible/generic_subject.yaml`` with their sources). Keeping the
functions lets the virtual experiment put the condyles exactly on the fossa.

Frame: the subject frame S (origin midway between the most superior points of the two
condyles, x anterior, y left, z up). At the reference (CT) pose the mandible frame M
coincides with S, so a mandible-fixed shape is described by its S coordinates there.

**Condyle head** — the upper cap of an ellipsoid with semi-axes (b, a, c) along the
joint axes e1 (antero-posterior, short axis), e2 (the long axis, pointing to +y) and
e3 = z (up). The joint axes are the subject axes rotated about z by ``axis_angle``
(+γ on the right, −γ on the left) so that the medial pole is posterior. The cap is
parametrised by s = (ŭ, v̆), |s| ≤ ρ_max (the "cap extent"):

    x(s) = C + b ŭ e1 + a v̆ e2 + c ŵ e3,   ŵ = √(1 − ŭ² − v̆²),   C = T − c e3

with T the most superior point (the condyle-top landmark). Outward unit normal:
n ∝ (ŭ/b) e1 + (v̆/a) e2 + (ŵ/c) e3.

**Fossa and eminence** — a height field z = Z(x, y) over the joint region, written in
the joint coordinates ξ = (p − T)·e1 (antero-posterior) and η_m = m (p − T)·e2
(medio-lateral, positive medially; m = +1 right, −1 left). Piecewise-linear slopes
joined by softplus corners sp(u) = ln(1 + eᵘ) of width w:

    Z = z_T + h_0 − k_e w [sp((ξ − ξ_1)/w) − sp((ξ − ξ_2)/w)]    eminence posterior slope
              − k_p w sp((ξ_p − ξ)/w) + k_a w sp((ξ − ξ_3)/w)       postglenoid wall, anterior face
              − k_m w sp((η_m − η_med)/w) − k_l w sp((η_lat − η_m)/w)  medial and lateral walls

with k_e = tan(eminence slope) and ξ_2 = ξ_1 + depth/k_e, so the slope between the
corners is exactly the eminence slope and the drop across it is the depth. dsp/du is
the logistic function, which gives the exact gradient. Normals of the fossa point
down, out of the skull, toward the joint space.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import Delaunay
from scipy.special import expit

__all__ = [
    "RESOLUTIONS",
    "CondyleShape",
    "FossaShape",
    "SmoothField",
    "condyle_mesh",
    "fossa_mesh",
    "rotation_z",
]

#: mesh sizes per resolution: condyle rings (vertices = 1 + 3 N (N + 1)) and the fossa
#: grid (n_xi, n_eta) (triangles = 2 (n_xi − 1)(n_eta − 1))
RESOLUTIONS = {
    "coarse": {"condyle_rings": 12, "fossa_grid": (40, 38)},     # 469 vertices, 2 886 triangles
    "default": {"condyle_rings": 36, "fossa_grid": (72, 70)},    # 3 997 vertices, 9 798 triangles
    "fine": {"condyle_rings": 60, "fossa_grid": (144, 136)},     # 10 981 vertices, 38 610 triangles
}


def rotation_z(angle: float) -> np.ndarray:
    """Rotation about z by ``angle`` rad, (3, 3); its columns are the rotated x, y, z axes."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _softplus(u):
    """sp(u) = ln(1 + eᵘ), overflow-free."""
    return np.logaddexp(0.0, u)


# --------------------------------------------------------------------------------------
# Condyle
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class CondyleShape:
    """Ellipsoidal condyle head (bone surface), fixed in the mandible frame.

    Attributes:
        top: (3,) m — most superior point T (the condyle-top landmark), subject frame at
            the reference pose.
        semi_axes: (3,) m — (b, a, c): antero-posterior, medio-lateral and vertical
            semi-axes along the joint axes e1, e2, e3.
        axis_angle: rad — rotation of the joint axes about z (+γ right, −γ left: the
            medial pole is posterior).
        cap_extent: ρ_max in (0, 1) — the cap is |s| ≤ ρ_max.
    """

    top: np.ndarray
    semi_axes: np.ndarray
    axis_angle: float
    cap_extent: float = 0.9

    def __post_init__(self):
        object.__setattr__(self, "top", np.asarray(self.top, dtype=float).reshape(3))
        object.__setattr__(self, "semi_axes", np.asarray(self.semi_axes, dtype=float).reshape(3))
        if np.any(self.semi_axes <= 0) or not 0.0 < self.cap_extent < 1.0:
            raise ValueError(f"condyle: semi-axes must be > 0 and cap_extent in (0, 1), got "
                             f"{self.semi_axes}, {self.cap_extent}")

    @property
    def axes(self) -> np.ndarray:
        """(3, 3): columns e1 (antero-posterior), e2 (long axis, +y side), e3 (up)."""
        return rotation_z(self.axis_angle)

    @property
    def center(self) -> np.ndarray:
        """(3,) m — ellipsoid centre C = T − c e3."""
        return self.top - self.semi_axes[2] * np.array([0.0, 0.0, 1.0])

    def points(self, s) -> np.ndarray:
        """Surface points x(s): s (..., 2) cap parameters (|s| ≤ 1) → (..., 3) m."""
        s = np.asarray(s, dtype=float)
        w = np.sqrt(np.clip(1.0 - s[..., 0] ** 2 - s[..., 1] ** 2, 0.0, None))
        local = np.stack([s[..., 0], s[..., 1], w], axis=-1) * self.semi_axes
        return self.center + local @ self.axes.T

    def normals(self, s) -> np.ndarray:
        """Outward unit normals n(s): s (..., 2) → (..., 3)."""
        s = np.asarray(s, dtype=float)
        w = np.sqrt(np.clip(1.0 - s[..., 0] ** 2 - s[..., 1] ** 2, 0.0, None))
        local = np.stack([s[..., 0], s[..., 1], w], axis=-1) / self.semi_axes
        n = local @ self.axes.T
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def implicit(self, p) -> np.ndarray:
        """Σ ((p − C)·e_i / semi_i)² − 1: zero on the ellipsoid; p (..., 3) m → (...,)."""
        q = (np.asarray(p, dtype=float) - self.center) @ self.axes
        return np.sum((q / self.semi_axes) ** 2, axis=-1) - 1.0

    def parameters_of(self, p) -> np.ndarray:
        """Cap parameters s (..., 2) of surface points p (..., 3) m (inverse of :meth:`points`)."""
        q = (np.asarray(p, dtype=float) - self.center) @ self.axes
        return q[..., :2] / self.semi_axes[:2]


def _ring_parameters(n_rings: int, cap_extent: float) -> np.ndarray:
    """Cap parameters on rings equally spaced in polar angle: (1 + 3N(N+1), 2).

    Ring i has 6i points; |s| = sin θ_i with θ_i = θ_max i / N, sin θ_max = ρ_max, so
    the points are about evenly spaced on the surface.
    """
    theta_max = np.arcsin(cap_extent)
    params = [np.zeros((1, 2))]
    for i in range(1, n_rings + 1):
        t = 2.0 * np.pi * np.arange(6 * i) / (6 * i)
        rho = np.sin(theta_max * i / n_rings)
        params.append(rho * np.column_stack([np.cos(t), np.sin(t)]))
    return np.vstack(params)


def condyle_mesh(shape: CondyleShape, n_rings: int) -> tuple[np.ndarray, np.ndarray]:
    """Open triangle mesh of the condyle cap, normals outward (up, toward the joint).

    Returns ``vertices (n, 3) m`` (subject frame at the reference pose) and
    ``faces (m, 3) int`` (counter-clockwise seen from outside).
    """
    s = _ring_parameters(n_rings, shape.cap_extent)
    faces = Delaunay(s).simplices.astype(np.int64)
    # counter-clockwise in (ŭ, v̆) maps to an outward normal because e1 × e2 = e3
    a, b, c = s[faces[:, 0]], s[faces[:, 1]], s[faces[:, 2]]
    signed_area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    faces[signed_area < 0] = faces[signed_area < 0][:, ::-1]
    return shape.points(s), faces


# --------------------------------------------------------------------------------------
# Fossa and eminence
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FossaShape:
    """Glenoid fossa and articular eminence as a height field z = Z(x, y) (skull frame).

    Lengths in m, angles in rad. ``top`` (3,) is the condyle top of this side at the
    reference pose (the origin of the joint coordinates ξ, η_m); ``medial_sign`` is +1
    on the right (medial = +y) and −1 on the left. ``height_offset`` h_0 is the roof
    level above the condyle top before the corners (set by the generator so that the
    condyle, offset by the cartilage layer, touches the fossa at the reference pose).
    See the module docstring for the formula.
    """

    top: np.ndarray
    axis_angle: float
    medial_sign: float
    height_offset: float
    depth: float
    eminence_slope: float
    eminence_start: float
    corner_width: float
    posterior_wall_position: float
    posterior_wall_slope: float
    anterior_face_position: float
    anterior_face_slope: float
    medial_wall_position: float
    medial_wall_slope: float
    lateral_wall_position: float
    lateral_wall_slope: float
    extent_xi: tuple = (-15e-3, 21e-3)
    extent_eta: tuple = (-17e-3, 17e-3)
    _axes: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "top", np.asarray(self.top, dtype=float).reshape(3))
        object.__setattr__(self, "_axes", rotation_z(self.axis_angle))
        if not (0.0 < self.eminence_slope < np.pi / 2 and self.depth > 0 and self.corner_width > 0):
            raise ValueError("fossa: need 0 < eminence_slope < 90°, depth > 0, corner_width > 0")

    @property
    def eminence_end(self) -> float:
        """ξ_2 = ξ_1 + depth / tan(slope), m."""
        return self.eminence_start + self.depth / np.tan(self.eminence_slope)

    def joint_coordinates(self, x, y):
        """(ξ, η) of subject-frame (x, y) arrays, m; η along e2 (η_m = medial_sign · η)."""
        dx, dy = np.asarray(x) - self.top[0], np.asarray(y) - self.top[1]
        e1, e2 = self._axes[:2, 0], self._axes[:2, 1]
        return dx * e1[0] + dy * e1[1], dx * e2[0] + dy * e2[1]

    def height_and_gradient(self, x, y):
        """Z(x, y) and its gradient: x, y (...) m → z (...) m, dZ/dx (...), dZ/dy (...)."""
        xi, eta = self.joint_coordinates(x, y)
        eta_m = self.medial_sign * eta
        w = self.corner_width
        k_e = np.tan(self.eminence_slope)
        u1, u2 = (xi - self.eminence_start) / w, (xi - self.eminence_end) / w
        up = (self.posterior_wall_position - xi) / w
        ua = (xi - self.anterior_face_position) / w
        um = (eta_m - self.medial_wall_position) / w
        ul = (self.lateral_wall_position - eta_m) / w
        z = (self.top[2] + self.height_offset
             - k_e * w * (_softplus(u1) - _softplus(u2))
             - self.posterior_wall_slope * w * _softplus(up)
             + self.anterior_face_slope * w * _softplus(ua)
             - self.medial_wall_slope * w * _softplus(um)
             - self.lateral_wall_slope * w * _softplus(ul))
        # d sp(u)/du = logistic(u)
        dz_dxi = (-k_e * (expit(u1) - expit(u2)) + self.posterior_wall_slope * expit(up)
                  + self.anterior_face_slope * expit(ua))
        dz_deta = self.medial_sign * (-self.medial_wall_slope * expit(um)
                                      + self.lateral_wall_slope * expit(ul))
        e1, e2 = self._axes[:2, 0], self._axes[:2, 1]
        return z, dz_dxi * e1[0] + dz_deta * e2[0], dz_dxi * e1[1] + dz_deta * e2[1]

    def height(self, x, y):
        """Z(x, y): x, y (...) m → z (...) m."""
        return self.height_and_gradient(x, y)[0]

    def with_height_offset(self, height_offset: float) -> FossaShape:
        """The same shape with another roof level h_0 (m)."""
        values = {k: getattr(self, k) for k in self.__dataclass_fields__ if not k.startswith("_")}
        values["height_offset"] = float(height_offset)
        return FossaShape(**values)


def fossa_mesh(shape: FossaShape, n_xi: int, n_eta: int, height=None) -> tuple[np.ndarray, np.ndarray]:
    """Open triangle mesh of the fossa/eminence over its (ξ, η) extent, normals down.

    ``height`` (optional) replaces ``shape.height``: a function (x, y) m → z m, e.g. a
    perturbed surface. Returns ``vertices (n_xi·n_eta, 3) m`` (subject frame) and
    ``faces (2 (n_xi − 1)(n_eta − 1), 3)``, wound so the normals point to −z (out of the
    skull bone, toward the joint space).
    """
    height = shape.height if height is None else height
    xi = np.linspace(*shape.extent_xi, n_xi)
    eta = np.linspace(*shape.extent_eta, n_eta)
    if shape.medial_sign < 0:
        # the left side runs η the other way so that a symmetric subject's left mesh is
        # the exact mirror image of the right one (same triangles, not just vertices)
        eta = eta[::-1]
    XI, ETA = np.meshgrid(xi, eta, indexing="ij")
    axes = shape._axes
    x = shape.top[0] + XI * axes[0, 0] + ETA * axes[0, 1]
    y = shape.top[1] + XI * axes[1, 0] + ETA * axes[1, 1]
    vertices = np.column_stack([x.ravel(), y.ravel(), np.asarray(height(x, y)).ravel()])
    index = np.arange(n_xi * n_eta).reshape(n_xi, n_eta)
    a, b = index[:-1, :-1].ravel(), index[1:, :-1].ravel()
    c, d = index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    # (a, b, c) is counter-clockwise seen from +z (ξ, η is a rotation of x, y);
    # reversed, the normal points down
    faces = np.concatenate([np.column_stack([a, c, b]), np.column_stack([a, d, c])])
    if shape.medial_sign < 0:
        faces = faces[:, ::-1]  # reversed η order flips the winding back to normals down
    return vertices, faces.astype(np.int64)


# --------------------------------------------------------------------------------------
# Smooth random fields (segmentation error)
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SmoothField:
    """A smooth scalar field f(p) = Σ_k A_k cos(κ_k·p + φ_k) (m), p (..., 3) m.

    With distinct wave vectors its spatial RMS is √(Σ A_k²/2). ``wave_vectors (K, 3)``
    rad/m, ``amplitudes (K,)`` m, ``phases (K,)`` rad. K = 0 is the zero field.
    """

    wave_vectors: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    amplitudes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    phases: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def random(cls, rng: np.random.Generator, rms: float, wavelength_range, n_waves: int = 8,
               planar: bool = False) -> SmoothField:
        """K = n_waves waves, random directions (in the x–y plane if ``planar``),
        wavelengths uniform in ``wavelength_range`` (m), amplitudes A = rms √(2/K)."""
        if rms == 0.0:
            return cls()
        direction = rng.normal(size=(n_waves, 3))
        if planar:
            direction[:, 2] = 0.0
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        wavelength = rng.uniform(*wavelength_range, size=n_waves)
        return cls(wave_vectors=direction * (2.0 * np.pi / wavelength)[:, None],
                   amplitudes=np.full(n_waves, rms * np.sqrt(2.0 / n_waves)),
                   phases=rng.uniform(0.0, 2.0 * np.pi, size=n_waves))

    @property
    def rms(self) -> float:
        """Spatial RMS, m."""
        return float(np.sqrt(np.sum(self.amplitudes ** 2) / 2.0))

    def value(self, p) -> np.ndarray:
        """f(p): (..., 3) m → (...) m."""
        p = np.asarray(p, dtype=float)
        if len(self.amplitudes) == 0:
            return np.zeros(p.shape[:-1])
        return np.cos(p @ self.wave_vectors.T + self.phases) @ self.amplitudes

    def gradient(self, p) -> np.ndarray:
        """∇f(p) = −Σ A_k sin(κ_k·p + φ_k) κ_k: (..., 3) m → (..., 3)."""
        p = np.asarray(p, dtype=float)
        if len(self.amplitudes) == 0:
            return np.zeros(p.shape)
        return -(np.sin(p @ self.wave_vectors.T + self.phases) * self.amplitudes) @ self.wave_vectors

    def to_dict(self) -> dict:
        """Plain lists, SI units (for YAML)."""
        return {"wave_vectors": self.wave_vectors.tolist(), "amplitudes": self.amplitudes.tolist(),
                "phases": self.phases.tolist()}
