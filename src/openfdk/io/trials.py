"""Marker trials from any supported file: C3D or TRC, chosen by the file extension."""

from __future__ import annotations

import hashlib
import os
import stat
from functools import lru_cache
from pathlib import Path

from .c3d import MarkerTrial

__all__ = ["TRIAL_FORMATS", "read_trial", "recorded_duration_s"]

#: extension -> reader description (for messages)
TRIAL_FORMATS = (".c3d", ".trc")


def read_trial(path: str | os.PathLike) -> MarkerTrial:
    """Read a marker trial: ``.c3d`` (:func:`~openfdk.io.c3d.read_c3d`) or ``.trc``
    (:func:`~openfdk.io.trc.read_trc`), positions in metres, times in seconds.

    The last two files read are kept (by path and a hash of their bytes; the trial's arrays
    are read-only): ``openfdk run`` reads the trial before it loads the model, so a bad
    file is reported at once and not after the model's minutes of set-up, and the analysis
    then takes the same trial without parsing it again (0.26 s for a 16 s, 72-marker
    treadmill TRC; hashing it takes 5 ms).

    Raises ValueError naming the file when the extension is neither."""
    name = os.fspath(path)
    try:
        regular = stat.S_ISREG(os.stat(name).st_mode)
        digest = hashlib.blake2b(Path(name).read_bytes(), digest_size=16).digest() if regular else None
    except OSError:
        regular = False
    if not regular:  # missing, unreadable, a FIFO: the reader's own one-line error
        return _read_trial.__wrapped__(name, None)
    return _read_trial(name, (os.path.realpath(name), digest))


@lru_cache(maxsize=2)
def _read_trial(path, key):
    """:func:`read_trial` of ``path`` (as given: the trial's messages name it); ``key``
    (real path, hash of the bytes) makes the same file's next read a cache hit."""
    suffix = Path(path).suffix.lower()
    if suffix == ".c3d":
        from .c3d import C3DError, read_c3d

        trial = read_c3d(path)
        _check_distances(trial, C3DError)
        return trial
    if suffix == ".trc":
        from .trc import read_trc

        return read_trc(path)
    raise ValueError(f"{os.fspath(path)}: unknown marker file type {suffix or '(no extension)'!r}; "
                     f"expected one of {', '.join(TRIAL_FORMATS)}")


def _check_distances(trial, error):
    """Raise ``error`` naming the frame, the time and the marker when a coordinate of
    ``trial`` (positions (n_frames, n_markers, 3) m) is farther than
    :data:`~openfdk.io.trc.MAX_MARKER_DISTANCE` from the origin (a TRC file is checked
    by its reader, which names the line)."""
    import numpy as np

    from .trc import MAX_MARKER_DISTANCE

    far = np.isfinite(trial.positions) & (np.abs(trial.positions) > MAX_MARKER_DISTANCE)
    if far.any():
        k, m, axis = (int(i) for i in np.argwhere(far)[0])
        raise error(f"{trial.source}: frame {k + 1} (time {trial.time[k]:g} s): marker {trial.labels[m]!r}: "
                    f"{'xyz'[axis]} = {trial.positions[k, m, axis]:g} m is beyond {MAX_MARKER_DISTANCE:g} m from the "
                    "origin, farther than any capture volume (a corrupt number, or the wrong POINT:UNITS?)")


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
