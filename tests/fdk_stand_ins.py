"""Stand-ins for the FDK solver's frame context in tests of the Newton iteration
(openfdk.fdk.newton): a closed-form f^FDK(α) in place of kinematics and recruitment."""

from types import SimpleNamespace

import numpy as np

from openfdk.fdk.residual import Evaluation


class Workspace:
    """A FrameWorkspace with nothing to carry."""

    def copy(self):
        return self


class ClosedFormResidual:
    """A stand-in for FDKContext: ``f(alpha)`` (n,) → f^FDK (n,) N, or None where the pose
    cannot be evaluated (a failed Evaluation). Records every α evaluated (``alphas``) and
    counts the calls (``calls``)."""

    def __init__(self, f, names=("x",)):
        self.f = f
        self.model = SimpleNamespace(fdk_dofs=[SimpleNamespace(name=n) for n in names])
        self.tracker = None
        self.solver = SimpleNamespace(forces=SimpleNamespace(by_kind={}))  # no force sets: no contacts
        self.alphas = []

    @property
    def calls(self):
        return len(self.alphas)

    def evaluate(self, k, alpha, ws, warm=None):
        alpha = np.array(alpha, dtype=float)
        self.alphas.append(alpha.copy())
        f = self.f(alpha)
        if f is None:
            return Evaluation(alpha, False, np.full(len(alpha), np.nan), "no pose here", "kinematics")
        return Evaluation(alpha, True, np.asarray(f, dtype=float), frame=SimpleNamespace(recruitment=None))
