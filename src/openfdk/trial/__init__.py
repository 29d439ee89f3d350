"""The one trial driver: times, per-frame steps, warm starts, progress, recording with a
structured per-frame status, checkpoints and interruption. Used by kinematics, inverse
dynamics, FDK and chunked runs; it depends on no analysis layer (docs/design.md §3)."""

from .driver import Recording, TrialInterrupted, drive
from .status import FrameReport, FrameStatus, Reason

__all__ = ["drive", "Recording", "TrialInterrupted", "FrameReport", "FrameStatus", "Reason"]
