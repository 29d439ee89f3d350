"""Row 0 of each of a list of scalar measures (FDK DOFs, springs) in one compiled call.

A thin user of :class:`~openfdk.model.compiled.CompiledMeasures` that keeps the Python
evaluation, measure by measure, as the reference (``batched = None``).
"""

from __future__ import annotations

import numpy as np

from .compiled import CompiledMeasures

__all__ = ["ScalarRows"]


class ScalarRows:
    """Row 0 of each of ``measures``: value (k,), M (k, n), b (k,).

    ``batched`` is the compiled program (set it to None to evaluate measure by measure
    in Python, the reference used by tests)."""

    def __init__(self, measures):
        self.measures = list(measures)
        self.batched = CompiledMeasures(self.measures, [[0]] * len(self.measures)) if self.measures else None

    def evaluate(self, state, order=1):
        """value (k,) in the measures' units; M (k, n_coords) = ∂value/∂q̂ for order ≥ 1
        (else None); b (k,) with value̋ = M v̇ + b for order 2 (else None)."""
        if self.batched is not None:
            return self.batched.evaluate(state, order)
        n = state.n_coords
        parts = [m.evaluate(state, order) for m in self.measures]
        value = np.array([p[0][0] for p in parts])
        M = np.array([p[1][0] for p in parts]).reshape(len(parts), n) if order >= 1 else None
        b = np.array([p[2][0] for p in parts]) if order >= 2 else None
        return value, M, b
