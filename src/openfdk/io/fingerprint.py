"""The fingerprint of a run's inputs, for checkpoints (``openfdk run --resume``).

A checkpoint may only be continued by the run that wrote it. The fingerprint hashes the
bytes of the model and trial files, of every file the model file refers to (meshes:
any text value of the model file naming an existing file relative to the model's
folder), and the analysis options. A changed mesh therefore gives another fingerprint
and the checkpoint is refused.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from .yamlfile import read_yaml


def referenced_files(model_path) -> list:
    """Files the model file ``model_path`` refers to: its text values (at any depth) that
    name an existing file relative to the model's folder, in file order, each once."""
    model_path = Path(model_path)
    base, found, seen = model_path.parent, [], set()
    from .opensim import is_osim

    if is_osim(model_path):  # an OpenSim model: its overlay (--with) and IK tasks, and the import options
        from .opensim.overlay import _REGISTERED, _key

        opts = _REGISTERED.get(_key(model_path))
        if opts is None:
            return []
        files = [(flag, p) for flag, p in (("--with", opts.overlay), ("--ik-tasks", opts.ik_tasks),
                                           ("--external-loads", opts.external_loads), ("--motion", opts.motion))
                 if p is not None]
        return files + [(f"--ignore {kind}", model_path) for kind in opts.ignore]

    walked = set()  # YAML aliases share containers: each is walked once (an alias bomb stays linear)

    def walk(value):
        if isinstance(value, (dict, list)):
            if id(value) in walked:
                return
            walked.add(id(value))
        if isinstance(value, dict):
            for v in value.values():
                walk(v)
        elif isinstance(value, list):
            for v in value:
                walk(v)
        elif isinstance(value, str) and value and value not in seen:
            seen.add(value)
            try:
                path = base / value
                if path.is_file():
                    found.append((value, path))
            except (OSError, ValueError):  # over-long or otherwise impossible names
                pass

    walk(read_yaml(model_path, what="model file"))
    return found


def _hash_file(h, path):
    """Feed the file's bytes to the hash ``h`` in 1 MiB blocks (a referenced mesh or a
    trial may be large; it is never held whole in memory). Returns ``h``."""
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(2**20), b""):
            h.update(block)
    return h


def run_fingerprint(model_path, trial_path=None, options=()) -> str:
    """SHA-256 (hex) of the model file, the files it refers to (name and bytes), the
    trial file (None: determinate run) and ``repr(options)``. The model file is read
    (and checked against its size limits, :mod:`openfdk.io.limits`) before anything
    else; the other files are hashed block by block."""
    from . import limits

    limits.check_file_bytes(model_path, "INPUT_FILE_BYTES", Path(model_path).name)  # also an .osim, before hashing
    files = referenced_files(model_path)  # a missing, malformed or too large model file: its one-line error
    h = hashlib.sha256()
    _hash_file(h, model_path)
    for name, path in files:
        h.update(b"\0" + name.encode() + b"\0" + _hash_file(hashlib.sha256(), path).digest())
    if trial_path is not None:
        if not Path(trial_path).is_file():
            raise FileNotFoundError(f"trial file {str(trial_path)!r} does not exist")
        h.update(b"\0trial\0")
        _hash_file(h, trial_path)
    h.update(repr(tuple(options)).encode())
    return h.hexdigest()


def file_stamp(path):
    """(resolved path, size in bytes, modification time in ns) of an existing file — the
    key of the per-process caches of parsed model files and loaded meshes (a changed
    file gets a new key) — or None when it cannot be read (the caller then loads the file
    itself and reports the problem)."""
    import os

    try:
        real = os.path.realpath(os.fspath(path))
        st = os.stat(real)
    except (OSError, TypeError, ValueError):
        return None
    return real, st.st_size, st.st_mtime_ns
