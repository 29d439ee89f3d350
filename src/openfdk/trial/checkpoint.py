"""Checkpoints of a running trial: finished frames written to the output folder as the
run goes, in parts, atomically, so that a killed run can be resumed.

A part ``OUT/.checkpoint/part-NNNNNN.pkl`` holds the frames finished since the previous
part, the index of the next frame to process and the step's warm-start state at that
point. It is written under a temporary name and renamed, so a part under its final name
is always whole. Every part carries the run's fingerprint (model, trial and options);
parts of another run are refused. The folder is removed when the final files are
written.
"""

from __future__ import annotations

import os
import pickle
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

CHECKPOINT_DIR = ".checkpoint"
DEFAULT_EVERY_FRAMES = 1000
DEFAULT_EVERY_SECONDS = 30.0


class CheckpointError(ValueError):
    """Saved checkpoints that cannot be used (another run's, or parts missing)."""


def _write_atomic(final, payload):
    """Pickle ``payload`` to ``final`` under a temporary name, then rename (a file under
    its final name is always whole)."""
    tmp = final.parent / f".{final.name}.tmp-{os.getpid()}"
    with open(tmp, "wb") as fh:
        pickle.dump(payload, fh, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, final)


def _read_own(path, fingerprint):
    """The payload of our checkpoint file ``path``; CheckpointError if another run's."""
    with open(path, "rb") as fh:
        payload = pickle.load(fh)  # our own files, written by _write_atomic
    if not isinstance(payload, dict) or payload.get("fingerprint") != fingerprint:
        raise CheckpointError(f"{path}: the checkpoint belongs to another run (model, meshes, trial or options "
                              f"differ); start again with --force")
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
        return sorted(p for p in self.folder.glob("part-*.pkl"))

    def due(self, n_pending):
        """True when ``n_pending`` finished frames should be written now."""
        if n_pending <= 0:
            return False
        return n_pending >= self.every_frames or time.monotonic() - self._last >= self.every_seconds

    def save(self, records, carry, next_frame):
        """Write one part atomically (temporary name, then rename)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        payload = {"fingerprint": self.fingerprint, "next_frame": int(next_frame), "records": records, "carry": carry}
        _write_atomic(self.folder / f"part-{self._index:06d}.pkl", payload)
        self._index += 1
        self._last = time.monotonic()

    def exists(self):
        return bool(self._parts())

    def load(self):
        """Saved (all parts joined) or None when there is none. Raises CheckpointError
        for another run's parts or a gap."""
        parts = self._parts()
        if not parts:
            return None
        records, carry, next_frame = [], None, 0
        for p in parts:
            payload = _read_own(p, self.fingerprint)
            records += payload["records"]
            carry, next_frame = payload["carry"], payload["next_frame"]
        self._index = len(parts)
        return Saved(records, carry, next_frame)

    def clear(self):
        shutil.rmtree(self.folder, ignore_errors=True)


class SegmentCheckpoints:
    """Finished segments of a chunked run (``openfdk run --chunks K``), one file each:
    ``folder/chunk-KKKKKK.pkl`` holding the fingerprint and the segment's result, written
    atomically as each segment finishes; :meth:`load` gives them back for ``--resume``."""

    def __init__(self, folder, fingerprint):
        self.folder = Path(folder)
        self.fingerprint = str(fingerprint)

    def save(self, index, result):
        """Keep the finished segment ``index`` (its result, any picklable object)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        _write_atomic(self.folder / f"chunk-{int(index):06d}.pkl", {"fingerprint": self.fingerprint, "result": result})

    def load(self):
        """{segment index: result} of the segments kept (empty when none); raises
        CheckpointError for another run's files."""
        if not self.folder.is_dir():
            return {}
        return {int(p.stem.split("-")[1]): _read_own(p, self.fingerprint)["result"]
                for p in sorted(self.folder.glob("chunk-*.pkl"))}

    def clear(self):
        shutil.rmtree(self.folder, ignore_errors=True)
