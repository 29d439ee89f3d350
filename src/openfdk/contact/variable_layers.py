"""Elastic layers whose thickness varies over the surfaces (OpenSim-JAM's variable
cartilage thickness; the fields: :mod:`.thickness`).

Each layer j has a modulus K_j (Pa) and a thickness h_j that is a constant, the vertices
surface's field h_A (at the contact vertex), the opposite surface's field h_B (at the
vertex's closest point on it), or their sum (OpenSim-JAM's lumped layer). At a contact
vertex i the law is the pair's law with the layers [K_j, h_ij] of that vertex:

    linear:      P = d / Σ_j h_ij/K_j,   dP/dd = 1 / Σ_j h_ij/K_j,   W = ½ P d
    non-linear:  :func:`.pressure_law.nonlinear_pressures_each` (Bei & Fregly 2004)

The thicknesses are fixed in each surface's body, so P depends on d alone along a
vertex's path within a triangle's reach: the loads still derive from W, and the
stiffness from dP/dd (:mod:`.elastic_foundation`), as for a uniform layer.
"""

from __future__ import annotations

import numpy as np

from .pressure_law import nonlinear_pressures_each


class VariableLayers:
    """The layers of one contact (module docstring).

    layers : [(K Pa, h m (the constant part), from A: bool, from B: bool)], 1 or 2;
    nonlinear : the non-linear law (else the linear one); h_A : (n_A,) m per vertex of
    the vertices surface or None; h_B : a :class:`~.thickness.TriangleThickness` of the
    opposite surface or None."""

    def __init__(self, layers, nonlinear, h_A, h_B):
        self.K = np.array([K for K, _, _, _ in layers], dtype=np.float64)
        self.h0 = np.array([h for _, h, _, _ in layers], dtype=np.float64)
        self.from_A = np.array([a for _, _, a, _ in layers], dtype=bool)
        self.from_B = np.array([b for _, _, _, b in layers], dtype=bool)
        self.nonlinear = bool(nonlinear)
        self.h_A, self.h_B = h_A, h_B

    def thickness(self, idx, closest_B):
        """h (k, m) m of each layer at the contact vertices idx (k,) of A, whose closest
        points on B are closest_B (k, 3) m in B's body frame."""
        k = len(idx)
        h = np.tile(self.h0, (k, 1))
        if self.from_A.any():
            h[:, self.from_A] += self.h_A[idx][:, None]
        if self.from_B.any():
            h[:, self.from_B] += self.h_B.at(closest_B)[:, None]
        return h

    def pressures(self, depth, idx, closest_B):
        """(P, dP/dd, W) each (k,) at depths (k,) m of the contact vertices idx."""
        depth = np.ascontiguousarray(depth, dtype=np.float64)
        h = self.thickness(idx, closest_B)
        if not self.nonlinear:
            modulus = 1.0 / np.sum(h / self.K, axis=1)
            return modulus * depth, modulus, 0.5 * modulus * depth * depth
        layers = np.empty((len(depth), len(self.K), 2))
        layers[:, :, 0] = self.K
        layers[:, :, 1] = h
        P, dP, W = np.empty_like(depth), np.empty_like(depth), np.empty_like(depth)
        nonlinear_pressures_each(depth, layers, P, dP, W)
        return P, dP, W

    def total_thickness(self):
        """The layers' total thickness Σ h_j (m) at its largest over the surfaces (the
        depth the non-linear law allows)."""
        total = float(self.h0.sum())
        if self.from_A.any():
            total += int(self.from_A.sum()) * float(self.h_A.max())
        if self.from_B.any():
            total += int(self.from_B.sum()) * float(self.h_B.h.max())
        return total

    def mean_modulus(self):
        """1/Σ h_j/K_j (N/m³) with each field at its mean: the law's slope at d = 0 for a
        typical vertex (reported, not used)."""
        h = self.h0.copy()
        if self.from_A.any():
            h[self.from_A] += float(np.mean(self.h_A))
        if self.from_B.any():
            h[self.from_B] += float(np.mean(self.h_B.h))
        return float(1.0 / np.sum(h / self.K))
