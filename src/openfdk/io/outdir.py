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


#: entries of an output folder that openfdk writes (a planted symbolic link there is refused)
WRITTEN_ENTRIES = (*RESULT_FILES, ".checkpoint", "plots", ".view.html.tmp", "kinematics.sto", "forces.sto",
                   "measures.csv", "measures.sto", "generalized_forces.csv")


def refuse_links(path, names=WRITTEN_ENTRIES):
    """OutputDirError when folder ``path`` holds a symbolic link at a name
    openfdk writes (``names``; ``plots/*`` too): a planted link is never followed."""
    p = Path(path)
    candidates = [p / n for n in names]
    if (p / "plots").is_dir() and not (p / "plots").is_symlink():
        candidates += sorted((p / "plots").iterdir())
    for c in candidates:
        if c.is_symlink():
            raise OutputDirError(f"{str(c)!r} is a symbolic link; openfdk does not write through links "
                                 "(remove it or choose another --out)")


def refuse_link(path):
    """OutputDirError when ``path`` is a symbolic link (checked with ``os.lstat``)."""
    if Path(path).is_symlink():
        raise OutputDirError(f"{str(path)!r} is a symbolic link; openfdk does not write through links "
                             "(remove it or choose another output)")


def write_new_file(path, data: bytes):
    """Write ``data`` to the new file ``path`` without following a link: a leftover
    regular file is replaced, a planted link is refused (OutputDirError); the file is
    opened with ``O_CREAT | O_EXCL | O_NOFOLLOW``."""
    path = Path(path)
    refuse_link(path)
    if path.exists():
        path.unlink()
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o644)
    except FileExistsError:  # created in between (a race with a planted link)
        raise OutputDirError(f"{str(path)!r} appeared while openfdk was writing it; not overwritten") from None
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)


def _partial(p):
    """True when ``p/summary.json`` marks an interrupted run (``"partial": true``)."""
    import json

    try:
        summary = json.loads((p / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(summary, dict) and summary.get("partial") is True


def check_output_dir(path, force=False, resume=False) -> Path:
    """Check the output folder ``path`` before a run and return it as a Path.

    Raises :class:`OutputDirError` when ``path`` is a file, cannot be created or written,
    or holds results of an earlier run while neither ``force`` (overwrite them) nor
    ``resume`` (continue that run) is set, or ``resume`` is set but there is nothing to
    continue (no ``.checkpoint`` and no summary marked partial: finished results are
    never overwritten by ``--resume``), or holds a symbolic link at a name openfdk writes.
    Creates the folder when missing.
    """
    if not str(path).strip():
        raise OutputDirError("the output folder is empty (--out ''); give a folder name")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputDirError(f"output folder {str(p)!r} is a file, not a folder")
    refuse_links(p)
    found = holds_results(p)
    if found and resume and not force and not (p / ".checkpoint").is_dir() and not _partial(p):
        raise OutputDirError(f"output folder {str(p)!r} already holds results ({', '.join(found)}) and no "
                             "checkpoint to resume (.checkpoint); use --force to overwrite them or choose "
                             "another --out")
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
