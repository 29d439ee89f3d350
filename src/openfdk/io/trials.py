"""Marker trials from any supported file: C3D or TRC, chosen by the file extension."""

from __future__ import annotations

import os
from pathlib import Path

from .c3d import MarkerTrial

__all__ = ["TRIAL_FORMATS", "read_trial"]

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
