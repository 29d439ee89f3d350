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


#: the other tables a run may write (each with its OpenSim twin), read beside the
#: results when present (:meth:`openfdk.results.run.RunResults.read`, the viewer)
OPTIONAL_RESULT_FILES = tuple(f"{name}.{ext}" for name in ("measures", "coordinates", "joint_loads", "moment_arms",
                                                           "generalized_forces", "grf")
                              for ext in ("csv", "sto")) + ("coordinates.mot", "kinematics.sto", "forces.sto")


def holds_results(path, optional=False) -> list:
    """Names of the result files (:data:`RESULT_FILES`; with ``optional`` also
    :data:`OPTIONAL_RESULT_FILES`) present in folder ``path``."""
    p = Path(path)
    names = (*RESULT_FILES, *OPTIONAL_RESULT_FILES) if optional else RESULT_FILES
    return [f for f in names if (p / f).is_file()] if p.is_dir() else []


def clear_results(path):
    """Remove an earlier run's results from folder ``path`` before ``--force`` writes
    new ones: every file :func:`holds_results` names, ``view.html`` and the figures in
    ``plots/``. A table or figure the new run does not write would otherwise stay and be
    read and shown as this run's (a ``moment_arms.csv`` of a run with ``--moment-arms``,
    plotted after a run without it)."""
    p = Path(path)
    stale = [p / f for f in (*holds_results(p, optional=True), "view.html") if (p / f).is_file()]
    plots = p / "plots"
    if plots.is_dir() and not plots.is_symlink():
        stale += [f for f in plots.iterdir() if f.suffix.lower() in (".png", ".svg", ".pdf") and f.is_file()]
    for f in stale:
        f.unlink()


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


#: suffixes of the files a run writes (tables, OpenSim storage and motion files, the
#: summary, the viewer, the figures): an input file with one of them inside the output
#: folder could be overwritten by the run that reads it
WRITTEN_SUFFIXES = (".csv", ".sto", ".mot", ".json", ".html", ".png")


def write_files(out_dir, files, error=ValueError) -> list:
    """Write ``files`` [(name, bytes)] into the folder ``out_dir`` (created; a symbolic
    link at one of the names is refused, an earlier file replaced: :func:`write_new_file`).
    Returns the paths written; a folder that cannot be made or written raises ``error``
    (a ValueError class) with one line naming it (``--out``)."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise error(f"--out: cannot create {str(out)!r} ({exc.strerror or exc})") from None
    if not out.is_dir():
        raise error(f"--out: {str(out)!r} is not a folder")
    paths = []
    try:
        for name, data in files:
            write_new_file(out / name, data)
            paths.append(out / name)
    except OutputDirError as exc:
        raise error(str(exc)) from None
    except OSError as exc:
        raise error(f"--out: cannot write into {str(out)!r} ({exc.strerror or exc})") from None
    return paths


def png_bytes(figure, dpi=110) -> bytes:
    """A matplotlib ``figure`` as PNG bytes (``dpi`` dots per inch)."""
    import io

    buf = io.BytesIO()
    figure.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def refuse_inputs_inside(path, inputs):
    """OutputDirError when one of ``inputs`` ((label, path) pairs: the option that named
    the file, and the file) lies inside the output folder ``path`` (at any depth, links
    resolved) with a suffix a run writes (:data:`WRITTEN_SUFFIXES`): the two-stage runs
    of docs/gait.md read ``coordinates.mot``, the very name a run writes, and a run with
    ``--out`` at its motion's folder replaced its own input."""
    if not str(path).strip():
        return  # no folder: check_output_dir's own error
    out = Path(os.path.realpath(path))
    for label, name in inputs:
        real = Path(os.path.realpath(name))
        if real.suffix.lower() in WRITTEN_SUFFIXES and real.is_file() and out in real.parents:
            raise OutputDirError(f"{str(name)!r} ({label}) is inside the output folder {str(path)!r}, where "
                                 "the run writes its results; choose another --out")


def _partial(p):
    """True when ``p/summary.json`` marks an interrupted run (``"partial": true``)."""
    import json

    try:
        summary = json.loads((p / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(summary, dict) and summary.get("partial") is True


def check_output_dir(path, force=False, resume=False) -> Path:
    """Check the output folder ``path`` before a run and return it as a Path (resolved
    when ``path`` goes through "..").

    Raises :class:`OutputDirError` when ``path`` is a file, cannot be created or written,
    or holds results of an earlier run while neither ``force`` (overwrite them) nor
    ``resume`` (continue that run) is set, or ``resume`` is set but there is nothing to
    continue (no ``.checkpoint`` and no summary marked partial: finished results are
    never overwritten by ``--resume``), or holds a symbolic link at a name openfdk writes.
    Creates the folder when missing.
    """
    if not str(path).strip():
        raise OutputDirError("the output folder is empty (--out ''); give a folder name")
    # a path through "..": the folder it names, links resolved (created parent by parent,
    # "sub/../../res" left an empty sub/ where nothing was asked for); use the returned path
    p = Path(os.path.realpath(path)) if ".." in Path(path).parts else Path(path)
    if p.exists() and not p.is_dir():
        raise OutputDirError(f"output folder {str(p)!r} is a file, not a folder")
    refuse_links(p)
    found = holds_results(p) or holds_results(p, optional=True)  # named: the main results, else the others
    if found and resume and not force and not (p / ".checkpoint").is_dir() and not _partial(p):
        raise OutputDirError(f"output folder {str(p)!r} already holds results ({', '.join(found)}) and no "
                             "checkpoint to resume (.checkpoint); use --force to overwrite them or choose "
                             "another --out")
    if found and not (force or resume):
        raise OutputDirError(f"output folder {str(p)!r} already holds results ({', '.join(found)}); "
                             "use --force to overwrite them or choose another --out")
    if found and force:
        clear_results(p)
    try:
        p.mkdir(parents=True, exist_ok=True)
        probe = p / f".openfdk-write-test-{uuid.uuid4().hex}"
        with open(probe, "w") as fh:
            fh.write("ok")
        os.remove(probe)
    except OSError as exc:
        raise OutputDirError(f"output folder {str(p)!r} is not writable: {exc.strerror or exc}") from None
    return p
