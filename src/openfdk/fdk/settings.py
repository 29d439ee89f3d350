"""FDK solver settings: model-file section ``fdk`` and per-DOF settings.

```yaml
fdk:
  tolerance: 1.0e-3        # N (N m for angular DOFs): converged when max |f^FDK| < tolerance
  max_iterations: 25       # Newton iterations per frame
  cold_max_iterations: 100 # ... for a frame whose previous frame did not converge (the first
                           # frame, after a failure): it starts from the DOFs' initial values
                           # or an unconverged iterate, not from a neighbouring solution
  jacobian: analytic       # or central (the paper's central differences)
  reuse_jacobian: true     # carry J between iterations and frames with Broyden updates
  line_search: true        # a refused step: a smaller trust region, then a golden-section search
                           # on the step length (false: plain Newton steps in the max_step box)
  extrapolate: true        # warm start α by extrapolating the previous frames: linear, or
                           # quadratic where that predicted the last frame better (fdk/warm_start.py)
  restart: true            # a frame that fails from its warm start is solved again from the
                           # previous frame's α, then from the DOFs' initial values, then
                           # from the previous α moved by ±2, ±4 max_steps along one DOF
                           # (after sub-steps, fdk/approach.py); failed frames are solved
                           # again backward from the next converged frame (fdk/analysis.py)
  contact_step: true       # Newton's step with the grid-mode contacts exact and the rest
                           # linear (fdk/contact_step.py); false: the linear model's step
fdk_dofs:
  tmj_r_normal: {measure: ..., max_step: 0.5, perturbation: 1.0e-3}   # file units
```

Defaults per DOF by unit: length DOFs max_step 1 mm, perturbation 1 µm; angle DOFs
0.05 rad and 1e-6 rad.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..model.modelfile import _wrap
from ..model.model import ModelError
from ..model.settings import checked_keywords

FDK = "fdk"
DEFAULT_MAX_STEP = {"length": 1e-3, "angle": 0.05}
DEFAULT_PERTURBATION = {"length": 1e-6, "angle": 1e-6}


@checked_keywords
@dataclass(frozen=True)
class FDKSettings:
    """tolerance : N or N m on max |f^FDK|; max_iterations; cold_max_iterations (a frame
    whose previous frame did not converge, :mod:`openfdk.fdk.analysis`); jacobian : "analytic" or
    "central"; line_search (trust region and golden section, :mod:`openfdk.fdk.trust_region`);
    reuse_jacobian (Broyden-updated J carried between
    iterations and frames, fdk/newton.py); extrapolate; restart (solve a failed frame
    again from the previous frame's α and from the DOFs' initial values,
    :func:`openfdk.fdk.newton.solve_frame_from`, and backward from the next converged
    frame, :class:`openfdk.fdk.analysis.FDKStep`); contact_step (Newton's step with the
    contacts exact, :mod:`openfdk.fdk.contact_step`); max_step, perturbation : (n_fdk,) SI,
    empty for the DOFs' own values and the defaults by unit (:func:`fdk_settings`).

    The model file's ``fdk`` section and ``AnalysisSettings.fdk``; exported as
    ``openfdk.FDKSettings``. A misspelt keyword is refused naming it, with a
    did-you-mean; a bad value (``jacobian``, ``tolerance``, ``max_iterations``) on
    construction."""

    tolerance: float = 1e-3
    max_iterations: int = 25
    cold_max_iterations: int = 100
    jacobian: str = "analytic"
    line_search: bool = True
    reuse_jacobian: bool = True
    extrapolate: bool = True
    restart: bool = True
    max_step: tuple = ()
    perturbation: tuple = ()
    golden_section_evaluations: int = 8
    contact_step: bool = True

    def __post_init__(self):
        if self.jacobian not in ("analytic", "central"):
            raise ModelError(f"fdk.jacobian must be 'analytic' or 'central', got {self.jacobian!r}")
        if not (self.tolerance > 0 and self.max_iterations >= 1 and self.cold_max_iterations >= 1):
            raise ModelError("fdk.tolerance must be > 0 and fdk.max_iterations, fdk.cold_max_iterations >= 1")

    def cold(self) -> "FDKSettings":
        """These settings for a frame that starts far from its root (a cold frame: no
        converged frame just before it): the larger of max_iterations and
        cold_max_iterations as the iteration limit."""
        return replace(self, max_iterations=max(self.max_iterations, self.cold_max_iterations))


def fdk_settings(model, settings=None, **overrides) -> FDKSettings:
    """FDK solver settings of a model analysed with ``settings`` (AnalysisSettings: the
    model file's ``fdk`` section; default none), the per-DOF values and defaults by
    unit, and keyword ``overrides``."""
    base = settings.fdk if settings is not None else FDKSettings()
    if isinstance(base, dict):
        base = FDKSettings(**base)
    base = replace(base, **overrides)  # an unknown override is refused with a did-you-mean
    steps, perts = [], []
    for dof in model.fdk_dofs:
        unit = dof.measure.units[0]
        steps.append(float(dof.settings.get("max_step", DEFAULT_MAX_STEP.get(unit, 1e-3))))
        perts.append(float(dof.settings.get("perturbation", DEFAULT_PERTURBATION.get(unit, 1e-6))))
    settings = replace(base, max_step=tuple(base.max_step) or tuple(steps),
                       perturbation=tuple(base.perturbation) or tuple(perts))
    if np.any(np.asarray(settings.max_step) <= 0):
        raise ModelError("FDK max_step values must be > 0")
    return settings


def load_fdk(b, data, ctx):
    ctx.keys(data, FDK, ["tolerance", "max_iterations", "cold_max_iterations", "jacobian", "line_search",
                         "reuse_jacobian", "extrapolate", "restart", "contact_step"])
    out = {}
    if "tolerance" in data:
        out["tolerance"] = ctx.number(data["tolerance"], "fdk.tolerance", positive=True)
    for key in ("max_iterations", "cold_max_iterations"):
        if key in data:
            n = data[key]
            if not isinstance(n, int) or isinstance(n, bool) or n < 1:
                raise ctx.error(f"fdk.{key}", f"expected a positive integer, got {n!r}")
            out[key] = n
    if "jacobian" in data:
        if data["jacobian"] not in ("analytic", "central"):
            raise ctx.error("fdk.jacobian", f"expected 'analytic' or 'central', got {data['jacobian']!r}")
        out["jacobian"] = data["jacobian"]
    for key in ("line_search", "reuse_jacobian", "extrapolate", "restart", "contact_step"):
        if key in data:
            if not isinstance(data[key], bool):
                raise ctx.error(f"fdk.{key}", f"expected true or false, got {data[key]!r}")
            out[key] = data[key]
    _wrap(ctx, FDK, lambda: b.elements.__setitem__(FDK, out))

