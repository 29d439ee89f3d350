"""Checkpoints of a running trial: finished frames written to the output folder as the
run goes, in parts, atomically, so that a killed run can be resumed.

A part ``OUT/.checkpoint/part-NNNNNN.npz`` holds the frames finished since the previous
part, the index of the next frame to process and the step's warm-start state at that
point. It is written under a temporary name and renamed, so a part under its final name
is always whole. Every part carries the run's fingerprint (model, trial and options);
parts of another run are refused. The folder is removed when the final files are
written.

A checkpoint folder is untrusted input (``--resume`` reads whatever is in OUT), so:

- each part has a JSON sidecar ``part-NNNNNN.json`` (written first) with the fingerprint
  and the SHA-256 of the part's bytes; the sidecar is read and the fingerprint and hash
  checked *before* the part is read;
- the part is not a pickle: it is an ``.npz`` of named arrays plus a JSON structure
  (:mod:`openfdk.trial.checkpoint_format`), read with ``numpy.load(allow_pickle=False)``
  and decoded by explicit type tags (only plain values, containers, numpy arrays and
  scalars and a fixed list of openfdk classes, rebuilt without calling code), so a
  crafted part — a pickle included — cannot run code;
- a truncated or otherwise unreadable part is a :class:`CheckpointError` naming it;
- files are created with ``O_EXCL | O_NOFOLLOW`` and a symlinked ``.checkpoint`` folder
  or part is refused, so a planted link never redirects a write.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
import time
from dataclasses import dataclass
from pathlib import Path

from .checkpoint_format import FormatError, decode, encode

CHECKPOINT_DIR = ".checkpoint"
DEFAULT_EVERY_FRAMES = 1000
DEFAULT_EVERY_SECONDS = 30.0


class CheckpointError(ValueError):
    """Saved checkpoints that cannot be used (another run's, or parts missing)."""


def _refuse_link(path):
    """CheckpointError when ``path`` is a symbolic link (a planted link is never followed)."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISLNK(st.st_mode):
        raise CheckpointError(f"{path}: is a symbolic link; openfdk does not follow links in the output folder "
                              f"(remove it)")


def _prepare_folder(folder):
    """Create the checkpoint folder (not following a planted link)."""
    _refuse_link(folder.parent)
    _refuse_link(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if not folder.is_dir():
        raise CheckpointError(f"{folder}: is not a folder")


def _write_new(path, data):
    """Write bytes ``data`` to a new file ``path`` (O_EXCL | O_NOFOLLOW: never an existing
    file or a link)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    fd = os.open(path, flags, 0o644)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)


def _write_atomic(final, payload):
    """Write ``payload`` (:func:`openfdk.trial.checkpoint_format.encode`, no pickle) to
    ``final`` under a temporary name, then rename (a file under its final name is always
    whole). The JSON sidecar (fingerprint, next frame and the
    part's SHA-256) is written first, so a part under its final name always has one."""
    data = encode(payload)
    side = {"fingerprint": payload["fingerprint"], "sha256": hashlib.sha256(data).hexdigest()}
    if "next_frame" in payload:
        side["next_frame"] = payload["next_frame"]
    for path, content in ((final.with_suffix(".json"), json.dumps(side).encode()), (final, data)):
        _refuse_link(path)
        tmp = path.parent / f".{path.name}.tmp-{os.getpid()}"
        if os.path.lexists(tmp):
            os.remove(tmp)  # a leftover of a killed run of this process id (a link is removed, not followed)
        _write_new(tmp, content)
        os.replace(tmp, path)


def _read_own(path, fingerprint):
    """The payload of our checkpoint file ``path``; CheckpointError if another run's,
    if its sidecar is missing or does not match its bytes, or if it cannot be read. The
    fingerprint is checked from the JSON sidecar before the part is decoded."""
    path = Path(path)
    side_path = path.with_suffix(".json")
    other = (f"{path}: the checkpoint belongs to another run (model, meshes, trial or options differ); "
             f"start again with --force")
    try:
        _refuse_link(path)
        _refuse_link(side_path)
        side = json.loads(side_path.read_text(encoding="utf-8"))
        data = path.read_bytes()
    except FileNotFoundError:
        raise CheckpointError(f"{path}: the checkpoint part has no sidecar {side_path.name} (written by another "
                              f"openfdk version or incomplete); start again with --force") from None
    except (OSError, ValueError) as exc:
        raise CheckpointError(f"{side_path}: unreadable checkpoint sidecar ({exc}); start again with --force") from None
    if not isinstance(side, dict) or not isinstance(side.get("fingerprint"), str):
        raise CheckpointError(f"{side_path}: not a checkpoint sidecar (no 'fingerprint'); start again with --force")
    if side["fingerprint"] != fingerprint:
        raise CheckpointError(other)
    if side.get("sha256") != hashlib.sha256(data).hexdigest():
        raise CheckpointError(f"{path}: the checkpoint part does not match its sidecar (cut short or changed); "
                              f"start again with --force")
    try:
        payload = decode(data)
    except FormatError as exc:  # any malformed part is one error naming it
        raise CheckpointError(f"{path}: unreadable checkpoint part ({exc}); start again with --force") from None
    if not isinstance(payload, dict) or payload.get("fingerprint") != fingerprint:
        raise CheckpointError(other)
    return payload


@dataclass(frozen=True)
class Saved:
    """records : [(frame, values)] in order; carry : the step's warm-start state;
    next_frame : the first frame still to process."""

    records: list
    carry: object
    next_frame: int


class Checkpoints:
    """Checkpoint parts of one run in ``folder`` (usually OUT/.checkpoint).

    fingerprint : str identifying the run's inputs; every_frames, every_seconds : a part
    is written when either many frames finished or that many seconds passed since the
    last part (whichever comes first).
    """

    def __init__(self, folder, fingerprint, every_frames=DEFAULT_EVERY_FRAMES, every_seconds=DEFAULT_EVERY_SECONDS):
        self.folder = Path(folder)
        self.fingerprint = str(fingerprint)
        self.every_frames = int(every_frames)
        self.every_seconds = float(every_seconds)
        self._last = time.monotonic()
        self._index = len(self._parts())

    def _parts(self):
        if not self.folder.is_dir():
            return []
        return sorted(p for p in self.folder.glob("part-[0-9][0-9][0-9][0-9][0-9][0-9].npz"))

    def due(self, n_pending):
        """True when ``n_pending`` finished frames should be written now."""
        if n_pending <= 0:
            return False
        return n_pending >= self.every_frames or time.monotonic() - self._last >= self.every_seconds

    def save(self, records, carry, next_frame):
        """Write one part atomically (temporary name, then rename)."""
        _prepare_folder(self.folder)
        payload = {"fingerprint": self.fingerprint, "next_frame": int(next_frame), "records": records, "carry": carry}
        _write_atomic(self.folder / f"part-{self._index:06d}.npz", payload)
        self._index += 1
        self._last = time.monotonic()

    def exists(self):
        return bool(self._parts())

    def load(self):
        """Saved (all parts joined) or None when there is none. Raises CheckpointError
        for another run's parts or a gap."""
        _refuse_link(self.folder)
        parts = self._parts()
        if not parts:
            return None
        records, carry, next_frame = [], None, 0
        for p in parts:
            payload = _read_own(p, self.fingerprint)
            records_ok = isinstance(payload.get("records"), list) and all(
                isinstance(r, tuple) and len(r) == 2 and isinstance(r[0], int) and isinstance(r[1], dict)
                for r in payload["records"])
            if not records_ok or not isinstance(payload.get("next_frame"), int):
                raise CheckpointError(f"{p}: not a checkpoint part of openfdk run; start again with --force")
            records += payload["records"]
            carry, next_frame = payload.get("carry"), payload["next_frame"]
        self._index = len(parts)
        return Saved(records, carry, next_frame)

    def clear(self):
        shutil.rmtree(self.folder, ignore_errors=True)


class SegmentCheckpoints:
    """Finished segments of a chunked run (``openfdk run --chunks K``), one file each:
    ``folder/chunk-KKKKKK.npz`` (same format as the parts) holding the fingerprint and the segment's result, written
    atomically as each segment finishes; :meth:`load` gives them back for ``--resume``."""

    def __init__(self, folder, fingerprint):
        self.folder = Path(folder)
        self.fingerprint = str(fingerprint)

    def save(self, index, result):
        """Keep the finished segment ``index`` (its SegmentResult)."""
        _prepare_folder(self.folder)
        _write_atomic(self.folder / f"chunk-{int(index):06d}.npz", {"fingerprint": self.fingerprint, "result": result})

    def load(self):
        """{segment index: result} of the segments kept (empty when none); raises
        CheckpointError for another run's files."""
        _refuse_link(self.folder)
        if not self.folder.is_dir():
            return {}
        return {int(p.stem.split("-")[1]): _read_own(p, self.fingerprint)["result"]
                for p in sorted(self.folder.glob("chunk-[0-9][0-9][0-9][0-9][0-9][0-9].npz"))}

    def clear(self):
        shutil.rmtree(self.folder, ignore_errors=True)
