"""Reading a YAML input file (model files, study files) with errors that name the file
and the line: the safe loader only, so nothing in a file is ever evaluated (libyaml's
C safe loader when PyYAML has it: about 10× faster on a mandible model file)."""

from __future__ import annotations

from pathlib import Path

import yaml

_SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def read_yaml(path, error=ValueError, what="file"):
    """The parsed content of the YAML file ``path``. Raises ``error`` (an exception
    class) with a one-line message when the file is missing ("<what> '<path>' does not
    exist") or malformed ("<name>: malformed YAML at line L, column C: <problem>")."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{what} {str(path)!r} does not exist")
    try:
        return yaml.load(path.read_text(), Loader=_SAFE_LOADER)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise error(f"{path.name}: malformed YAML{where}: {getattr(exc, 'problem', exc)}") from None
