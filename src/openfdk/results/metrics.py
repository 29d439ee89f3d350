"""Agreement metrics between a computed and a measured (reference) time series.

Andersen et al. 2017, "Model evaluation": Root-Mean-Square Deviation (RMSD), the squared
Pearson correlation coefficient (r²) and the Sprague & Geers (2004) magnitude (M) and
phase (P) errors. For computed samples c_k and measured samples m_k, k = 1…n:

* RMSD = sqrt( (1/n) Σ (c_k − m_k)² )                       (unit of the signals)
* r²   = ( Σ (c_k − c̄)(m_k − m̄) )² / ( Σ (c_k − c̄)² Σ (m_k − m̄)² )
* M    = sqrt( Σ c_k² / Σ m_k² ) − 1                          (M < 0: c is smaller than m)
* P    = arccos( Σ m_k c_k / sqrt(Σ m_k² Σ c_k²) ) / π        (0 in phase … 1 opposite)

All functions take two 1-D arrays of equal length in the same unit and are NaN-aware:
a sample pair is dropped when c_k or m_k is NaN (or ±inf), and the metric is computed on
the remaining pairs. When no pair remains every metric is NaN. Undefined values are NaN
too (see each function); no function warns or raises for them.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MetricsInputError", "compare", "r_squared", "rmsd", "sprague_geers"]


class MetricsInputError(ValueError):
    """The computed and measured series cannot be compared (shape, dimension)."""


def _valid_pairs(c, m) -> tuple[np.ndarray, np.ndarray]:
    """The finite pairs (c_k, m_k) of two equal-length 1-D series, as float arrays."""
    c = np.asarray(c, dtype=float)
    m = np.asarray(m, dtype=float)
    if c.ndim != 1 or m.ndim != 1:
        raise MetricsInputError(
            f"computed c and measured m must be 1-D series; got shapes {c.shape} and {m.shape}")
    if c.shape != m.shape:
        raise MetricsInputError(
            f"computed c has {c.size} samples but measured m has {m.size}; expected equal lengths")
    keep = np.isfinite(c) & np.isfinite(m)
    return c[keep], m[keep]


def rmsd(c, m) -> float:
    """Root-mean-square deviation sqrt(mean((c − m)²)) over the finite pairs.

    Args: c : (n,) computed; m : (n,) measured, same unit (e.g. m or N).
    Returns: RMSD in the unit of c and m; NaN if no finite pair remains.
    """
    c, m = _valid_pairs(c, m)
    if c.size == 0:
        return math.nan
    return float(np.sqrt(np.mean((c - m) ** 2)))


def r_squared(c, m) -> float:
    """Squared Pearson correlation coefficient r² ∈ [0, 1] over the finite pairs.

    r² = (Σ (c−c̄)(m−m̄))² / (Σ (c−c̄)² Σ (m−m̄)²).

    Args: c : (n,) computed; m : (n,) measured, any unit.
    Returns: r² (dimensionless). NaN when fewer than two finite pairs remain or when
    either series is constant over them (all values exactly equal): the correlation of a
    constant is undefined (0/0), and NaN keeps it out of a nan-mean rather than
    pretending the shapes agree or disagree.
    """
    c, m = _valid_pairs(c, m)
    if c.size < 2 or np.ptp(c) == 0.0 or np.ptp(m) == 0.0:
        return math.nan
    dc, dm = c - c.mean(), m - m.mean()
    s_cm, s_cc, s_mm = float(dc @ dm), float(dc @ dc), float(dm @ dm)
    if s_cc == 0.0 or s_mm == 0.0:
        return math.nan
    return min(1.0, s_cm * s_cm / (s_cc * s_mm))


def sprague_geers(c, m) -> tuple[float, float]:
    """Sprague & Geers magnitude and phase errors (M, P) over the finite pairs.

    M = sqrt(Σc²/Σm²) − 1 (0: same magnitude; −0.2: c is 20 % smaller than m);
    P = arccos(Σmc / sqrt(Σm²·Σc²))/π ∈ [0, 1] (0: in phase; 0.5: orthogonal;
    1: opposite sign), with the cosine clipped to [−1, 1] against round-off.

    Args: c : (n,) computed; m : (n,) measured (the reference), same unit.
    Returns: (M, P), both dimensionless. M is NaN when Σm² = 0 (no reference
    magnitude); P is NaN when Σm² = 0 or Σc² = 0; both NaN without finite pairs.
    """
    c, m = _valid_pairs(c, m)
    s_mm, s_cc, s_mc = float(m @ m), float(c @ c), float(m @ c)
    M = math.sqrt(s_cc / s_mm) - 1.0 if s_mm > 0.0 else math.nan
    if s_mm > 0.0 and s_cc > 0.0:
        cosine = min(1.0, max(-1.0, s_mc / math.sqrt(s_mm * s_cc)))
        P = math.acos(cosine) / math.pi
    else:
        P = math.nan
    return M, P


def compare(c, m) -> dict:
    """All four metrics of computed c against measured m.

    Args: c : (n,) computed; m : (n,) measured, same unit; NaN pairs dropped.
    Returns: dict(rmsd=… (unit of the inputs), r2=…, M=…, P=…), floats (NaN when
    undefined, see :func:`rmsd`, :func:`r_squared`, :func:`sprague_geers`).
    """
    M, P = sprague_geers(c, m)
    return {"rmsd": rmsd(c, m), "r2": r_squared(c, m), "M": M, "P": P}
