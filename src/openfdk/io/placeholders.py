"""Input files that hold no data at all: an empty file, or a Git LFS pointer.

A repository cloned without Git LFS leaves, where each large file was, a small text file
beginning ``version https://git-lfs.github.com/spec/v1`` (jam-resources keeps its knee
meshes, trials and models so); a failed download leaves an empty file. Either would be
reported as a malformed STL, C3D, TRC or XML file; :func:`placeholder` names it.
"""

from __future__ import annotations

#: how a Git LFS pointer file begins
LFS_POINTER = b"version https://git-lfs.github.com/spec/"


def placeholder(data: bytes) -> str | None:
    """Why the first bytes ``data`` of an input file hold no data at all, or None."""
    if not data.strip():
        return "the file is empty"
    if data.startswith(LFS_POINTER):
        return ("is a Git LFS pointer, not the file's content: its repository was cloned without its large "
                "files (run 'git lfs pull' there)")
    return None


def placeholder_of_file(path) -> str | None:
    """:func:`placeholder` of the file ``path``'s first 200 bytes (None when unreadable)."""
    try:
        with open(path, "rb") as f:
            return placeholder(f.read(200))
    except OSError:
        return None
