"""OpenSim function elements → the function dicts of :mod:`openfdk.model.coordinate_functions`.

:func:`function_element` finds the function of a ``TransformAxis``, a
``CoordinateCouplerConstraint`` or a ``MultiplierFunction``, and :func:`function_spec`
turns it into the dict :func:`~openfdk.model.coordinate_functions.function_from_spec`
builds, in the file's units (OpenSim 4.6 sources, ``OpenSim/Common``, for the element
and property names; OpenSim 3.x and 4.x files):

===========================  =========================================================
``<Constant>``               ``value`` (default 0) → ``{type: constant, value}``
``<LinearFunction>``         ``coefficients`` = slope, intercept (default ``1 0``)
                             → ``{type: linear, slope, intercept}``
``<PolynomialFunction>``     ``coefficients``, highest power first (default ``1``)
                             → ``{type: polynomial, coefficients}``
``<SimmSpline>``             ``x``, ``y`` → ``{type: simm_spline, x, y}``
``<NaturalCubicSpline>``,    ``x``, ``y`` → ``{type: natural_cubic_spline, x, y}`` (OpenSim
``<natCubicSpline>``         reads both as SimmSpline, and so does openfdk)
``<GCVSpline>``              ``half_order`` m, ``error_variance`` (default 0), ``x``, ``y``
                             → ``{type: gcv_spline, x, y, degree: 2m − 1}``; ``weights``
                             and ``coefficients`` are ignored, as OpenSim 4 does (it
                             refits with unit weights); an error variance other than 0
                             (a smoothing fit) is refused
``<PiecewiseLinearFunction>`` ``x``, ``y`` → ``{type: piecewise_linear, x, y}``
``<MultiplierFunction>``     ``scale`` (default 1) and the inner function in
                             ``<function>`` → ``{type: multiplier, scale, function: {…}}``
===========================  =========================================================

A property element left out takes OpenSim's default (OpenSim writes only properties that
differ from their defaults). OpenSim 4.6 writes the number lists of these functions
(``x``, ``y``, a LinearFunction's ``coefficients``) with 6 significant digits, but the
scalars and a PolynomialFunction's ``coefficients`` with 17; openfdk, like OpenSim on
reading, takes the numbers as the file has them.

Any other function type (``StepFunction``, ``Sine``, ``PiecewiseConstantFunction``,
``MultivariatePolynomialFunction``, …) is refused by name, as is an element OpenSim's
class does not have. Every error is an :class:`OsimError` of one line: file, line, the
element and what is wrong; the dicts returned are already checked by
``function_from_spec`` (x increasing, enough points, …) so that those errors, too, name
the element's line.
"""

from __future__ import annotations

import re

from ...model.coordinate_functions import function_from_spec
from .errors import OsimError, where

__all__ = ["FUNCTION_TAGS", "UNSUPPORTED_FUNCTION_TAGS", "function_element", "function_spec"]

#: OpenSim function element → openfdk function type
FUNCTION_TAGS = {
    "Constant": "constant",
    "LinearFunction": "linear",
    "PolynomialFunction": "polynomial",
    "SimmSpline": "simm_spline",
    "NaturalCubicSpline": "natural_cubic_spline",
    "natCubicSpline": "natural_cubic_spline",
    "GCVSpline": "gcv_spline",
    "PiecewiseLinearFunction": "piecewise_linear",
    "MultiplierFunction": "multiplier",
}

#: OpenSim's other Function classes (OpenSim 4.6): recognised, and refused
UNSUPPORTED_FUNCTION_TAGS = (
    "StepFunction", "Sine", "PiecewiseConstantFunction", "MultivariatePolynomialFunction",
    "ExpressionBasedFunction", "ActiveForceLengthCurve", "FiberForceLengthCurve",
    "ForceVelocityCurve", "ForceVelocityInverseCurve", "TendonForceLengthCurve",
)

#: owner element → (its function property, whether OpenSim also reads the function
#: element directly in the owner, named after the property or unnamed)
_FUNCTION_PROPERTY = {
    "TransformAxis": ("function", True),
    "CoordinateCouplerConstraint": ("coupled_coordinates_function", False),
    "Coordinate": ("prescribed_function", False),
    "MultiplierFunction": ("function", False),
}

# each supported element: its properties and OpenSim's defaults (None: no default)
_PROPERTIES = {
    "Constant": {"value": "0"},
    "LinearFunction": {"coefficients": "1 0"},
    "PolynomialFunction": {"coefficients": "1"},
    "SimmSpline": {"x": "", "y": ""},
    "NaturalCubicSpline": {"x": "", "y": ""},
    "natCubicSpline": {"x": "", "y": ""},
    "GCVSpline": {"half_order": "0", "error_variance": "0", "x": "", "y": "",
                  "weights": None, "coefficients": None},
    "PiecewiseLinearFunction": {"x": "", "y": ""},
    "MultiplierFunction": {"scale": "1"},
}

# a decimal number as OpenSim writes it; no nan, inf, hex or digit separators
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z", re.ASCII)   # ASCII digits only
_INTEGER = re.compile(r"[+-]?\d+\Z", re.ASCII)


def _is_function_tag(tag) -> bool:
    return isinstance(tag, str) and (tag in FUNCTION_TAGS or tag in UNSUPPORTED_FUNCTION_TAGS
                                     or tag.endswith(("Function", "Spline", "Curve")))


def _elements(element):
    """The child elements (no comments or processing instructions)."""
    return [c for c in element if isinstance(c.tag, str)]


def _label(source, element) -> str:
    """``where(source, element)`` followed by the nearest two named (or function) owners, e.g.
    ``gait.osim: line 812: SimmSpline (TransformAxis 'translation1' of CustomJoint 'knee_r')``."""
    owners = []
    node = element.getparent()
    while node is not None and len(owners) < 2:
        if isinstance(node.tag, str) and (node.get("name") or node.tag in FUNCTION_TAGS):
            owners.append(f"{node.tag} {node.get('name')!r}" if node.get("name") else node.tag)
        node = node.getparent()
    text = where(source, element)
    return f"{text} ({' of '.join(owners)})" if owners else text


def function_element(parent, source):
    """The function element of ``parent`` — a ``TransformAxis``, a
    ``CoordinateCouplerConstraint``, a ``Coordinate`` (its ``prescribed_function``) or a
    ``MultiplierFunction`` — or None when it has none; the caller then applies OpenSim's
    default (for a TransformAxis of a 4.x file OpenSim 4.6 keeps its property default,
    ``Constant(0)``, even when the axis names a coordinate: checked with ``opensim``).

    The forms OpenSim 4.6 reads (``AbstractProperty::readFromXMLParentElement`` and
    ``Object::updateFromXMLNode``; checked with the ``opensim`` package):

    * every owner: the property element wrapping one function,
      ``<function><LinearFunction>…</LinearFunction></function>`` (a coupler:
      ``<coupled_coordinates_function>``);
    * a TransformAxis only (its ``function`` is a one-object property): the function
      element directly inside it, named after the property, ``<LinearFunction
      name="function">`` (what OpenSim 4 writes), or without a name attribute.

    OpenSim ignores a function element anywhere else (a coupler's or a
    MultiplierFunction's without the wrapper, a TransformAxis's with another name): it
    then has no function, or silently Constant(0). Such an element is refused here, as
    are two functions and a wrapper that does not hold exactly one element."""
    prop, abbreviated = _FUNCTION_PROPERTY.get(parent.tag, ("function", False))
    children = _elements(parent)
    wrappers = [c for c in children if c.tag == prop]
    direct = [c for c in children if _is_function_tag(c.tag)]
    if len(wrappers) + len(direct) > 1:
        tags = ", ".join(f"<{c.tag}> (line {c.sourceline})" for c in wrappers + direct)
        raise OsimError(f"{_label(source, parent)}: more than one function: {tags}")
    if wrappers:
        inner = _elements(wrappers[0])
        if len(inner) != 1:
            what = "is empty" if not inner else f"holds {len(inner)} elements ({', '.join(c.tag for c in inner)})"
            raise OsimError(f"{_label(source, wrappers[0])}: <{prop}> {what}; expected one function element")
        return inner[0]
    if not direct:
        return None
    node = direct[0]
    name = node.get("name")
    if not abbreviated:
        raise OsimError(f"{_label(source, node)}: OpenSim reads the function of a {parent.tag} only "
                        f"inside <{prop}>…</{prop}>; it ignores this element")
    if name not in (None, "", prop):
        raise OsimError(f"{_label(source, node)}: a function directly in a {parent.tag} must be named "
                        f"{prop!r} or not at all (OpenSim ignores this one); wrap it in <{prop}> instead")
    return node


def _numbers(text, label, name):
    tokens = (text or "").split()
    for tok in tokens:
        if not _NUMBER.match(tok):
            raise OsimError(f"{label}: <{name}>: {tok[:40]!r} is not a finite number")
    return [float(tok) for tok in tokens]


def function_spec(element, source) -> dict:
    """The function dict (see :func:`~openfdk.model.coordinate_functions.function_from_spec`)
    of the OpenSim function ``element`` (an lxml element whose tag is the function type),
    in the file's units. ``source`` names the file in error messages."""
    label = _label(source, element)
    tag = element.tag
    if not isinstance(tag, str):
        raise OsimError(f"{source}: line {element.sourceline}: expected a function element")
    if tag not in FUNCTION_TAGS:
        known = ", ".join(FUNCTION_TAGS)
        if tag in UNSUPPORTED_FUNCTION_TAGS:
            raise OsimError(f"{label}: the OpenSim function type {tag} is not supported "
                            f"(supported: {known})")
        raise OsimError(f"{label}: unknown function type {tag!r} (supported: {known})")

    allowed = _PROPERTIES[tag]
    texts = {}
    for child in _elements(element):
        name = child.tag
        if tag == "MultiplierFunction" and (name == "function" or _is_function_tag(name)):
            continue                                  # the inner function, found below
        if name not in allowed:
            raise OsimError(f"{label}: unexpected element <{name}> (line {child.sourceline}); "
                            f"{tag} has {', '.join(f'<{p}>' for p in allowed) or 'no properties'}"
                            + (" and a function" if tag == "MultiplierFunction" else ""))
        if name in texts:
            raise OsimError(f"{label}: <{name}> is given twice (line {child.sourceline})")
        if _elements(child):
            raise OsimError(f"{label}: <{name}> (line {child.sourceline}) must hold text, not elements")
        texts[name] = child.text or ""

    def get(name):
        return texts[name] if name in texts else allowed[name]

    def one_number(name):
        values = _numbers(get(name), label, name)
        if len(values) != 1:
            raise OsimError(f"{label}: <{name}> must be one number, got {len(values)}")
        return values[0]

    kind = FUNCTION_TAGS[tag]
    if kind == "constant":
        spec = {"type": kind, "value": one_number("value")}
    elif kind == "linear":
        c = _numbers(get("coefficients"), label, "coefficients")
        if len(c) != 2:
            raise OsimError(f"{label}: <coefficients> must be 2 numbers (slope, intercept), got {len(c)}")
        spec = {"type": kind, "slope": c[0], "intercept": c[1]}
    elif kind == "polynomial":
        spec = {"type": kind, "coefficients": _numbers(get("coefficients"), label, "coefficients")}
    elif kind == "gcv_spline":
        half = get("half_order").strip()
        if not _INTEGER.match(half) or len(half) > 9:   # (int() refuses over 4300 digits)
            raise OsimError(f"{label}: <half_order> must be an integer from 1 to 3, got {half[:20]!r}")
        half = int(half)
        if half < 1:
            raise OsimError(f"{label}: <half_order> must be at least 1, got {half}")
        if half > 3:
            raise OsimError(f"{label}: <half_order> {half} (degree {2 * half - 1}) is not supported "
                            "(openfdk supports half_order 1, 2, 3: degree 1, 3, 5)")
        variance = one_number("error_variance")
        if variance != 0.0:
            raise OsimError(f"{label}: <error_variance> {variance:g}: OpenSim then fits a smoothing "
                            "spline, which openfdk does not reproduce; only 0 (interpolation) is supported")
        spec = {"type": kind, "x": _numbers(get("x"), label, "x"), "y": _numbers(get("y"), label, "y"),
                "degree": 2 * half - 1}
    elif kind == "multiplier":
        inner = function_element(element, source)
        if inner is None:
            raise OsimError(f"{label}: no function to multiply")
        spec = {"type": kind, "scale": one_number("scale"), "function": function_spec(inner, source)}
    else:                                             # the x-y functions
        spec = {"type": kind, "x": _numbers(get("x"), label, "x"), "y": _numbers(get("y"), label, "y")}

    def error(path, message):
        return OsimError(f"{label}: {message}")

    function_from_spec(spec, "", error)               # the checks, with this element's line
    return spec
