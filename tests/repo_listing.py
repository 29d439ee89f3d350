"""The repository's files as git tracks them, or — outside a git checkout (an sdist, an
exported tree) — the files on disk that .gitignore does not exclude, so that the tests
that read the tree run either way."""

from __future__ import annotations

import fnmatch
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def gitignore_patterns(root=ROOT):
    path = root / ".gitignore"
    lines = path.read_text().splitlines() if path.is_file() else []
    return [ln.strip() for ln in lines if ln.strip() and not ln.startswith("#")] + [".git/"]


def is_ignored(rel, patterns):
    """Whether the relative path ``rel`` (posix) matches a .gitignore pattern: a folder
    (``dir/``: the path below it), a path with a slash (from the root) or a name glob."""
    parts = rel.split("/")
    for pat in patterns:
        if pat.endswith("/"):
            folder = pat.rstrip("/")
            if "/" in folder:
                if rel.startswith(folder + "/"):
                    return True
            elif folder in parts[:-1] or any(fnmatch.fnmatch(p, folder) for p in parts[:-1]):
                return True
        elif "/" in pat:
            if fnmatch.fnmatch(rel, pat.lstrip("/")):
                return True
        elif any(fnmatch.fnmatch(p, pat) for p in parts):
            return True
    return False


def repo_files(*patterns, root=ROOT):
    """Relative paths (Path) of the files matching the git pathspecs ``patterns`` (name
    globs like ``*.py`` or folders like ``examples``)."""
    out = subprocess.run(["git", "ls-files", *patterns], cwd=root, capture_output=True, text=True)
    if out.returncode == 0 and out.stdout.strip():
        return [Path(p) for p in out.stdout.split("\n") if p]
    ignore = gitignore_patterns(root)
    found = []
    for path in root.rglob("*"):
        rel = path.relative_to(root).as_posix()
        if not path.is_file() or is_ignored(rel, ignore):
            continue
        if any(rel == p or rel.startswith(p.rstrip("/") + "/") or fnmatch.fnmatch(path.name, p) for p in patterns):
            found.append(Path(rel))
    return sorted(found)
