"""Names of model items that are safe in file names and XML.

The names of bodies (and their frames and markers), measures, joints, constraints,
drivers, FDK DOFs, coordinates, couplers, force elements, contacts and wrapping surfaces
become file names (``Geometry/<contact>_<side>.obj``) and XML (``<Body name="…">``) in
``openfdk export-opensim``. Whether a model comes from a model file
(:mod:`openfdk.model.modelfile`, which names the entry) or is built in Python
(:class:`openfdk.model.builder.ModelBuilder`, the force-element and contact adders), the
same rule applies: :func:`name_problem`.
"""

from __future__ import annotations

__all__ = ["NAME_FORBIDDEN", "name_problem", "label_problem", "check_name"]

#: characters a name may not contain: path separators and XML's reserved characters
#: (control characters are refused too)
NAME_FORBIDDEN = frozenset('/\\<>&"')


def _control(text):
    return sorted({c for c in text if ord(c) < 32 or ord(c) == 127})


def name_problem(name):
    """Why ``name`` cannot name a model item (None when it can): a path separator, an XML
    reserved character or a control character, or ``..``."""
    if not isinstance(name, str):
        return None  # the section readers report non-text names
    bad = sorted({c for c in name if c in NAME_FORBIDDEN} | set(_control(name)))
    if bad:
        return f"name {name!r} contains {', '.join(repr(c) for c in bad)}; names may not contain '/', '\\', " \
               f"'<', '>', '&', '\"' or control characters (they become file names and XML in exports)"
    if ".." in name:
        return f"name {name!r} contains '..'"
    return None


def label_problem(label):
    """Why ``label`` (a marker's trial label, written as XML text by exports but never
    used in a file name) cannot be used: control characters, which XML cannot hold."""
    bad = _control(label) if isinstance(label, str) else []
    if bad:
        return f"label {label!r} contains {', '.join(repr(c) for c in bad)}; labels may not contain control characters"
    return None


def check_name(name, what):
    """Raise :class:`~openfdk.model.model.ModelError` ``"<what> name '…' contains …"``
    when :func:`name_problem` rejects ``name``."""
    problem = name_problem(name)
    if problem:
        from .model import ModelError

        raise ModelError(f"{what} {problem}")
