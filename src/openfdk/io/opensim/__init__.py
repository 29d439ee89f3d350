"""OpenSim models in: ``.osim`` files (OpenSim 3.x and 4.x) read into openfdk models.

One more way into the same :class:`~openfdk.model.builder.ModelBuilder` (docs/design.md §3):
the XML is read into records (:mod:`.document`), the records become an openfdk model
mapping in the model-file format (:mod:`.to_model`), and the model-file loader builds
it. After ``build()`` nothing downstream knows where the model came from. Coverage,
element by element: docs/opensim-import.md.
"""

from __future__ import annotations

from .errors import OsimError

__all__ = ["OsimError", "read_osim", "is_osim"]


def is_osim(path) -> bool:
    """Whether ``path`` names an OpenSim model (by its suffix, ``.osim``)."""
    return str(path).lower().endswith(".osim")


def read_osim(path, ignore=(), mesh_dirs=(), keep_welds=()):
    """(model mapping, info) of an ``.osim``: the mapping is in openfdk's model-file
    format (SI units); info has ``dropped`` (type, name, line) of the elements left out
    on request (``ignore``: element types such as ``Thelen2003Muscle``, ``Mesh`` or
    ``forces``) and ``merged_bodies`` {welded body: body it is part of}. Any element
    openfdk does not read and that is not ignored raises OsimError naming its type, name
    and line. ``keep_welds``: WeldJoints (names, or True for all) whose bodies stay
    apart, joined by the weld's rows (their loads are then reported)."""
    from .document import read_document
    from .to_model import model_dict

    doc = read_document(path, ignore=ignore)
    if doc.unsupported:
        kind, name, line = doc.unsupported[0]
        more = f" (and {len(doc.unsupported) - 1} more unsupported elements)" if len(doc.unsupported) > 1 else ""
        label = f"{kind} {name!r}" if name else kind
        kinds = list(dict.fromkeys(k for k, _, _ in doc.unsupported))  # every type, once: one run to leave all out
        leave = (f"leave it out with --ignore {kind}" if len(kinds) == 1 else
                 "leave them out with " + " ".join(f"--ignore {k}" for k in kinds[:8])
                 + (f" (and {len(kinds) - 8} more types)" if len(kinds) > 8 else ""))
        raise OsimError(f"{doc.source}: line {line}: {label} is not supported by openfdk's OpenSim import{more}; "
                        f"{leave}")
    data, info = model_dict(doc, mesh_dirs, ignore, keep_welds)
    info["dropped"] = [{"type": k, "name": n, "line": line} for k, n, line in doc.ignored]
    _warn_unmatched(doc, ignore)
    return data, info


def _warn_unmatched(doc, ignore):
    """Warn of an ``ignore`` type that matched nothing and looks mistyped: several types
    in one (``Mesh,Thelen2003Muscle``), or a name close to an element type the model
    has (``Thelen2003Muscl``). A real type the model simply lacks (a habitual ``--ignore
    Mesh``) is no mistake and passes without one."""
    import warnings

    from ...model.plausibility import PlausibilityWarning
    from ..yamlfile import did_you_mean

    present = {kind for kind, _, _ in doc.ignored} | ({"Mesh"} if doc.geometry else set()) | {"forces"}
    for kind in sorted(set(ignore) - present):
        if any(ch in kind for ch in ", ;"):
            why = "one OpenSim type per --ignore, e.g. --ignore Mesh --ignore Thelen2003Muscle"
        else:
            hint = did_you_mean(kind, sorted(doc.element_types - present))
            if not hint:
                continue
            why = hint.lstrip("; ")
        warnings.warn(f"{doc.source}: --ignore {kind!r}: the model has no element of this type ({why})",
                      PlausibilityWarning, stacklevel=3)
