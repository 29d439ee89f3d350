"""Structured per-frame status: an enum and fields, not text.

Every frame of every analysis ends with a :class:`FrameReport`: whether it converged,
failed or was not run (interrupted), why (a :class:`Reason`), the solver's iteration
count, its final residual, and a human-readable message. Chunk stitching, summaries and
exit codes read the enums; the message is for people only.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np


class FrameStatus(enum.Enum):
    """Outcome of one frame."""

    CONVERGED = "converged"
    FAILED = "failed"
    NOT_RUN = "not_run"  # the run was interrupted before this frame finished


class Reason(enum.Enum):
    """Why a frame ended as it did (CONVERGED for converged frames)."""

    CONVERGED = "converged"
    UNOBSERVABLE = "unobservable"  # visible markers + constraints leave coordinates free
    SINGULAR = "singular"  # a singular kinematic system, or no FDK restoring force
    ITERATION_LIMIT = "iteration_limit"
    KINEMATICS = "kinematics"  # the frame's kinematics failed (seen by dynamics / FDK)
    RECRUITMENT = "recruitment"  # recruitment infeasible or not converged
    JACOBIAN = "jacobian"  # the FDK Jacobian could not be computed
    LINE_SEARCH = "line_search"  # no FDK step length reduced the residual
    NO_PROGRESS = "no_progress"  # the FDK iteration stalled: its steps no longer reduce the residual's merit
    FAILED = "failed"  # any other failure (the message says which)
    NOT_RUN = "not_run"


@dataclass(frozen=True)
class FrameReport:
    """status : FrameStatus; reason : Reason; iterations : solver iterations (int);
    residual : the solver's final residual in its own unit (max |Φ| in m or rad for
    kinematics, max |C f − d| in N for recruitment, max |f^FDK| in N or N m for FDK;
    NaN when unknown); message : '' when converged, else the reason in words."""

    status: FrameStatus
    reason: Reason = Reason.CONVERGED
    iterations: int = 0
    residual: float = float("nan")
    message: str = ""

    @property
    def converged(self) -> bool:
        return self.status is FrameStatus.CONVERGED

    def well_typed(self) -> bool:
        """Whether every field has its type (a checkpoint's report is rebuilt field by
        field, untrusted: trial/checkpoint_format.py)."""
        return (isinstance(self.status, FrameStatus) and isinstance(self.reason, Reason)
                and isinstance(self.iterations, (int, np.integer)) and not isinstance(self.iterations, bool)
                and isinstance(self.residual, (int, float, np.floating)) and not isinstance(self.residual, bool)
                and isinstance(self.message, str))

    @classmethod
    def ok(cls, iterations=0, residual=float("nan")):
        return cls(FrameStatus.CONVERGED, Reason.CONVERGED, int(iterations), float(residual), "")

    @classmethod
    def ok_many(cls, residuals, iterations=0):
        """[:meth:`ok` (iterations, r) for r in residuals] (a trial solved in compiled
        chunks: its frames' reports at ≈ 0.3 µs each instead of ≈ 2 µs; the same
        values, frozen like the others)."""
        new, base = object.__new__, {"status": FrameStatus.CONVERGED, "reason": Reason.CONVERGED,
                                     "iterations": int(iterations), "message": ""}
        out = []
        for r in np.asarray(residuals, dtype=float).tolist():
            report = new(cls)
            report.__dict__.update(base, residual=r)
            out.append(report)
        return out

    @classmethod
    def failed(cls, reason: Reason, message: str, iterations=0, residual=float("nan")):
        return cls(FrameStatus.FAILED, reason, int(iterations), float(residual), str(message))

    def describe(self, frame: int, time: float) -> str:
        """'' when converged, else ``frame k (t = … s): message`` (k in the numbering of
        the trial the report belongs to)."""
        if self.converged:
            return ""
        return f"frame {frame} (t = {time:.4f} s): {self.message}"


NOT_RUN = FrameReport(FrameStatus.NOT_RUN, Reason.NOT_RUN, 0, float("nan"), "not run (the analysis was interrupted)")


def frame_messages(reports, times, offset=0):
    """Per-frame messages (tuple of str) from reports (nf,) and times (nf,) s; frame
    numbers start at ``offset``."""
    return tuple(r.describe(offset + k, float(t)) for k, (r, t) in enumerate(zip(reports, times)))
