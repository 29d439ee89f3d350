"""The output folder of a run, checked before any computation.

:func:`check_output_dir` makes sure results can be written (the folder is created and a
probe file written and removed) and that nothing finished is overwritten by accident: a
folder that already holds results is refused unless the user asked to overwrite it
(``force``) or to continue the run found there (``resume``).
"""

from __future__ import annotations

import os
import uuid
from pathlib import Path

#: files whose presence means a folder holds results of an earlier run
RESULT_FILES = ("summary.json", "kinematics.csv", "forces.csv")


class OutputDirError(ValueError):
    """The output folder cannot be used; the message names it and says what to do."""


def holds_results(path) -> list:
    """Names of the result files (:data:`RESULT_FILES`) present in folder ``path``."""
    p = Path(path)
    return [f for f in RESULT_FILES if (p / f).is_file()] if p.is_dir() else []


def check_output_dir(path, force=False, resume=False) -> Path:
    """Check the output folder ``path`` before a run and return it as a Path.

    Raises :class:`OutputDirError` when ``path`` is a file, cannot be created or written,
    or holds results of an earlier run while neither ``force`` (overwrite them) nor
    ``resume`` (continue that run) is set. Creates the folder when missing.
    """
    if not str(path).strip():
        raise OutputDirError("the output folder is empty (--out ''); give a folder name")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputDirError(f"output folder {str(p)!r} is a file, not a folder")
    found = holds_results(p)
    if found and not (force or resume):
        raise OutputDirError(f"output folder {str(p)!r} already holds results ({', '.join(found)}); "
                             "use --force to overwrite them or choose another --out")
    try:
        p.mkdir(parents=True, exist_ok=True)
        probe = p / f".openfdk-write-test-{uuid.uuid4().hex}"
        with open(probe, "w") as fh:
            fh.write("ok")
        os.remove(probe)
    except OSError as exc:
        raise OutputDirError(f"output folder {str(p)!r} is not writable: {exc.strerror or exc}") from None
    return p
