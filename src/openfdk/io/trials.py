"""Marker trials from any supported file: C3D or TRC, chosen by the file extension."""

from __future__ import annotations

import os
from pathlib import Path

from .c3d import MarkerTrial

__all__ = ["TRIAL_FORMATS", "read_trial", "recorded_duration_s"]

#: extension -> reader description (for messages)
TRIAL_FORMATS = (".c3d", ".trc")


def read_trial(path: str | os.PathLike) -> MarkerTrial:
    """Read a marker trial: ``.c3d`` (:func:`~openfdk.io.c3d.read_c3d`) or ``.trc``
    (:func:`~openfdk.io.trc.read_trc`), positions in metres, times in seconds.

    Raises ValueError naming the file when the extension is neither."""
    suffix = Path(path).suffix.lower()
    if suffix == ".c3d":
        from .c3d import read_c3d

        return read_c3d(path)
    if suffix == ".trc":
        from .trc import read_trc

        return read_trc(path)
    raise ValueError(f"{os.fspath(path)}: unknown marker file type {suffix or '(no extension)'!r}; "
                     f"expected one of {', '.join(TRIAL_FORMATS)}")


def recorded_duration_s(path: str | os.PathLike) -> float | None:
    """Recorded duration (s) of a trial file from its header only — C3D: (frames − 1)/rate
    from the header (:func:`~openfdk.io.c3d.inspect_c3d`, pure Python); TRC: (NumFrames −
    1)/DataRate from lines 2–3 — or None when the header does not tell it (another format,
    an unreadable or incomplete header: reading the trial reports such a file)."""
    suffix = Path(path).suffix.lower()
    try:
        if suffix == ".c3d":
            from .c3d import inspect_c3d

            layout = inspect_c3d(path)
            rate, frames = layout.rate, layout.n_frames
        elif suffix == ".trc":
            from .trc import header_fields

            header = header_fields(path)
            rate, frames = float(header["DataRate"]), int(float(header["NumFrames"]))
        else:
            return None
    except (OSError, ValueError, KeyError):
        return None
    return max(frames - 1, 0) / rate if rate > 0 else None
