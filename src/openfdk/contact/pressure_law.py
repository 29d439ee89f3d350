"""Elastic-foundation pressure laws: the pressure P(d) (Pa) of a depth d (m), its slope
dP/dd (Pa/m) and the elastic energy per unit area W(d) (J/m²), per contact vertex.

* **linear** (openfdk's default, the paper's): P = k d with the pressure modulus k
  (N/m³); W = ½ k d².
* **non-linear** (Bei & Fregly 2004; OpenSim-JAM's ``nonlinear`` formulation, Smith et al.
  2018): a layer of thickness h and modulus K = E (1 − ν)/((1 + ν)(1 − 2ν)) compressed
  by d carries

      P = −K ln(1 − d/h),      W = −K ((d − h) ln(1 − d/h) − d),

  (so dW/dd = P, and P ≈ K d/h for d ≪ h: the linear law with k = K/h). Two layers in
  series (one on each surface, OpenSim-JAM's ``use_lumped_contact_model`` false) share
  the pressure and add their depths: d = Σ_j h_j (1 − exp(−P/K_j)), solved for P by
  Newton's method from P = 0 (the residual is increasing and concave in P, so the
  iterates rise monotonically to the root); dP/dd = 1/Σ_j (h_j/K_j) exp(−P/K_j) and W is
  the sum of the layers' energies at their depths d_j = h_j (1 − exp(−P/K_j)).

The non-linear pressure grows without bound as d → Σ h; beyond d_cap = 0.999 Σ h it
continues along its tangent at d_cap (C¹, finite forces for a vertex through the whole
layer; a depth the law does not describe — check the thickness and max_depth).

Layers are rows [K (Pa), h (m)] of a (m, 2) array, m = 1 or 2.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["CAP_FRACTION", "layer_modulus", "nonlinear_pressures", "nonlinear_pressures_each", "linear_pressures"]

#: fraction of the total thickness beyond which the non-linear law continues linearly
CAP_FRACTION = 0.999


def layer_modulus(E, nu):
    """K = E (1 − ν)/((1 + ν)(1 − 2ν)) (Pa) of a layer of Young's modulus E (Pa) and
    Poisson's ratio ν (the confined, "aggregate" modulus of an elastic foundation)."""
    return E * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))


def linear_pressures(k, depth):
    """(P, dP/dd, W) arrays (k,) of the linear law P = k d; depth (k,) m, k N/m³."""
    depth = np.asarray(depth, dtype=np.float64)
    return k * depth, np.full(depth.shape, float(k)), 0.5 * k * depth * depth


@njit(cache=True)
def _solve(d, layers):
    """(P, dP/dd, W) of the layers at total depth d ≥ 0 below the cap."""
    m = layers.shape[0]
    if m == 1:
        K, h = layers[0, 0], layers[0, 1]
        ln = math.log1p(-d / h)  # ln(1 − d/h), accurate for small d
        return -K * ln, K / (h - d), -K * ((d - h) * ln - d)
    P = 0.0
    for _ in range(100):
        g = -d
        dg = 0.0
        for j in range(m):
            K, h = layers[j, 0], layers[j, 1]
            e = math.exp(-P / K)
            g -= h * math.expm1(-P / K)  # h (1 − e), accurate for small P
            dg += h / K * e
        step = -g / dg
        P += step
        if abs(step) <= 1e-15 * P:
            break
    dg = 0.0
    W = 0.0
    for j in range(m):
        K, h = layers[j, 0], layers[j, 1]
        e = math.exp(-P / K)
        dg += h / K * e
        dj = -h * math.expm1(-P / K)
        W += -K * ((dj - h) * (-P / K) - dj)  # ln(1 − d_j/h_j) = −P/K_j
    return P, 1.0 / dg, W


@njit(cache=True)
def nonlinear_pressures(depth, layers, P, dP, W):
    """Fill P, dP, W (k,) for depths (k,) m ≥ 0 of the layers (m, 2) [K Pa, h m]."""
    total = 0.0
    for j in range(layers.shape[0]):
        total += layers[j, 1]
    d_cap = CAP_FRACTION * total
    P_c, dP_c, W_c = _solve(d_cap, layers)
    for i in range(depth.shape[0]):
        d = depth[i]
        if d <= d_cap:
            P[i], dP[i], W[i] = _solve(d, layers)
        else:  # tangent continuation beyond the cap
            e = d - d_cap
            P[i] = P_c + dP_c * e
            dP[i] = dP_c
            W[i] = W_c + P_c * e + 0.5 * dP_c * e * e


@njit(cache=True)
def nonlinear_pressures_each(depth, layers, P, dP, W):
    """Fill P, dP, W (k,) for depths (k,) m ≥ 0, each with its own layers (k, m, 2)
    [K Pa, h m] (a thickness that varies over the surfaces, :mod:`.variable_layers`);
    the cap and its tangent continuation per vertex, as :func:`nonlinear_pressures`."""
    for i in range(depth.shape[0]):
        L = layers[i]
        total = 0.0
        for j in range(L.shape[0]):
            total += L[j, 1]
        d_cap = CAP_FRACTION * total
        d = depth[i]
        if d <= d_cap:
            P[i], dP[i], W[i] = _solve(d, L)
        else:
            P_c, dP_c, W_c = _solve(d_cap, L)
            e = d - d_cap
            P[i] = P_c + dP_c * e
            dP[i] = dP_c
            W[i] = W_c + P_c * e + 0.5 * dP_c * e * e
