"""The error of the OpenSim reader, in a module of its own (no numba, no numpy)."""

from ...model.errors import ModelError


class OsimError(ModelError):
    """An ``.osim`` (or OpenSim ``.xml``) file that openfdk cannot read exactly. The
    message is one line naming the file, the line, the element type and its name, e.g.
    ``gait.osim: line 812: SimmSpline (TransformAxis 'translation1' of joint 'knee_r'):
    x values are not increasing``."""


def where(source, element, what=None):
    """``"file: line N: Type 'name'"`` for an lxml element (``what`` overrides the type)."""
    kind = what or element.tag
    name = element.get("name")
    label = f"{kind} {name!r}" if name else kind
    return f"{source}: line {element.sourceline}: {label}"
