"""How each joint of a model was declared, kept beside its constraint rows for exports
(``model.joints``; :mod:`openfdk.io.osim_joints` writes them as OpenSim joints).

The analysis never reads these records: a joint acts through its rows in
``model.constraints``. The record keeps what the rows no longer show — the joint type,
its two frames, the rows turned into FDK DOFs, an OpenSim-style joint's axes and
functions, a coupler's function.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class JointRecord:
    """A declared joint.

    name : str; type : "weld", "spherical", "revolute", "prismatic", "point_on_plane"
    (:meth:`~openfdk.model.builder.ModelBuilder.add_joint`), "custom" (an OpenSim
    SpatialTransform, :func:`~openfdk.model.coordinate_joint.add_coordinate_joint`) or
    "coupler" (a CoordinateCouplerConstraint); parent, child : qualified frames
    "body.frame" (empty for a coupler); normal : (3,) unit plane normal in the parent
    frame (point_on_plane); fdk_rows : labels of the rows made FDK DOFs (x, y, z, rx, …);
    rotations, translations : 3 :class:`~openfdk.model.coordinate_joint.Axis` each
    (custom, SI); independent, dependent, function : a coupler's coordinates and its
    PiecewisePolynomial (SI)."""

    name: str
    type: str
    parent: str = ""
    child: str = ""
    normal: np.ndarray | None = None
    fdk_rows: tuple = ()
    rotations: tuple = ()
    translations: tuple = ()
    independent: str = ""
    dependent: str = ""
    function: object = None


def record_joint(b, record: JointRecord):
    """Append ``record`` to the builder's ``joints`` (the Model field ``joints``)."""
    b.elements["joints"] = tuple(b.elements.get("joints", ())) + (record,)
