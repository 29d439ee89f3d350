"""The validated, immutable model (Pinocchio's *Model*: never modified by an analysis)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .components import GROUND, Body, Frame
from .constraints import Constraint, FDKDof, MarkerSet
from .errors import ModelError  # defined in a light module (study drivers), re-exported here
from .state import BodyStates


@dataclass(frozen=True, eq=False)
class Model:
    """A complete model. Build it with :class:`~openfdk.model.builder.ModelBuilder` or
    :func:`~openfdk.io.modelfile.load_model`.

    Attributes
    ----------
    name : str
    bodies : tuple of Body, ``bodies[0]`` is the ground
    frames : dict qualified name "body.frame" -> Frame
    markers : MarkerSet
    measures : dict name -> Measure (user-named measures)
    constraints : tuple of Constraint (joints and drivers)
    fdk_dofs : tuple of FDKDof
    gravity_W : (3,) m/s²

    Force elements, each kind a typed field (tuples, in declaration order). Every kind
    is one force set with one interface (:mod:`openfdk.forces.forceset`): generalised
    forces Q (n,) on the bodies and, when asked, their stiffness ∂Q/∂q̂ (n, n).

    muscles : Muscle (path + strength model; recruited)
    ligaments : Ligament (path + Blankevoort1991Ligament)
    springs : Spring (scalar measure + LinearSpring)
    contacts : ContactElement (elastic foundation between two meshes)
    loads : ExternalLoad (force and moment time functions at a body point)
    unilateral_reactions : UnilateralReaction (one-sided joint rows, recruited)
    visuals : Visual (display meshes of bodies, for the viewer; no forces)
    coordinates : Coordinate (OpenSim-style joint coordinates, each a named measure;
        :mod:`openfdk.model.coordinate_joint`)
    external_loads : DataLoad (measured loads from a sampled file, e.g. ground
        reactions; :mod:`openfdk.forces.data_loads`)
    actuators : CoordinateActuator (recruitment columns weighted by their optimal force:
        OpenSim's reserve and residual actuators; :mod:`openfdk.forces.actuators`)
    joints : JointRecord (how each joint and coupler was declared, for exports;
        :mod:`openfdk.model.joint_records`; the rows are in ``constraints``)
    tasks : CoordinateTask (soft rows of marker tracking beside the markers, Eq. 4:
        OpenSim's IKCoordinateTasks; :mod:`openfdk.model.tasks`)

    The model is purely physical: how it is analysed (kinematics window, recruitment,
    FDK solver) is an :class:`~openfdk.model.settings.AnalysisSettings` kept apart and
    passed to the analyses (``settings=``).
    """

    name: str
    bodies: tuple
    frames: dict
    markers: MarkerSet
    measures: dict
    constraints: tuple
    fdk_dofs: tuple
    gravity_W: np.ndarray
    muscles: tuple = ()
    ligaments: tuple = ()
    springs: tuple = ()
    contacts: tuple = ()
    loads: tuple = ()
    unilateral_reactions: tuple = ()
    visuals: tuple = ()
    coordinates: tuple = ()
    tasks: tuple = ()
    external_loads: tuple = ()
    actuators: tuple = ()
    joints: tuple = ()
    source: str = ""

    # -- look-ups -------------------------------------------------------------------
    def body(self, name) -> Body:
        for b in self.bodies:
            if b.name == name:
                return b
        raise ModelError(f"unknown body {name!r}; bodies are {[b.name for b in self.bodies]}")

    def frame(self, qualified) -> Frame:
        try:
            return self.frames[qualified]
        except KeyError:
            raise ModelError(f"unknown frame/point {qualified!r}") from None

    @property
    def moving_bodies(self):
        return tuple(b for b in self.bodies if b.column >= 0)

    @property
    def n_coords(self):
        """Number of virtual displacements, 6 per moving body."""
        return 6 * len(self.moving_bodies)

    @property
    def n_constraint_rows(self):
        return sum(c.size for c in self.constraints)

    def coordinate_names(self):
        """Names of the 6 n_moving q̂/v components, e.g. 'mandible.vx', 'mandible.wz'."""
        out = []
        for b in self.moving_bodies:
            out += [f"{b.name}.{c}" for c in ("x", "y", "z", "rx", "ry", "rz")]
        return out

    def constraint_row_names(self):
        return [r for c in self.constraints for r in c.row_names]

    def initial_state(self) -> BodyStates:
        """A new workspace at the model's reference pose with zero velocities."""
        return BodyStates(
            [b.p_WB0 for b in self.bodies],
            [b.quat_WB0 for b in self.bodies],
            [b.column for b in self.bodies],
        )

    def describe(self):
        """A short multi-line text summary."""
        lines = [
            f"model {self.name!r}: {len(self.moving_bodies)} moving bodies, "
            f"{self.n_coords} coordinates, {self.n_constraint_rows} constraint rows, "
            f"{self.markers.size} markers, {len(self.fdk_dofs)} FDK DOFs"
        ]
        for c in self.constraints:
            lines.append(f"  {c.kind:6s} {c.name} ({c.joint_type}, {c.size} rows)")
        return "\n".join(lines)


__all__ = ["Model", "ModelError", "GROUND", "Constraint", "FDKDof"]
