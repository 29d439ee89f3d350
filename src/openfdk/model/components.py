"""Static model components: bodies, frames (points with orientation) and markers.

A body's frame origin is its centre of mass (docs/design.md §1: q_i = [r_i; p_i] with r_i the
centre-of-mass position). All lengths in m, masses in kg, inertia in kg m² about the
centre of mass, expressed in the body frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

GROUND = "ground"


def _frozen_array(a, shape, what):
    arr = np.array(a, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{what}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: contains non-finite values {arr.tolist()}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Body:
    """A rigid body.

    Attributes
    ----------
    name : str
    mass : float, kg
    inertia_B : (3, 3) kg m², about the centre of mass, in the body frame
    p_WB0 : (3,) m, initial (reference) position of the centre of mass in world
    quat_WB0 : (4,) initial orientation, Euler parameters scalar first
    fixed : bool, a fixed body keeps its initial pose and has no coordinates
    equilibrium : bool, whether the body's Newton–Euler equations enter the
        inverse dynamics (False for a body moved by the data whose loads are unknown)
    index : int, position in ``Model.bodies``
    column : int, first column of the body's 6 virtual displacements in q̂, or -1
    inertia_as_given : bool, an inertia that violates the triangle inequality is used as
        given, with a warning, instead of refused (an OpenSim model's: OpenSim takes it)
    """

    name: str
    mass: float
    inertia_B: np.ndarray
    p_WB0: np.ndarray
    quat_WB0: np.ndarray
    fixed: bool = False
    equilibrium: bool = True
    index: int = -1
    column: int = -1
    inertia_as_given: bool = False


@dataclass(frozen=True, eq=False)
class Frame:
    """A frame fixed on a body: origin ``p_BF`` (3,) m and orientation ``R_BF`` (3, 3).

    Points are frames whose orientation is the body's.
    """

    name: str  # qualified: "body.frame"
    body: str
    p_BF: np.ndarray
    R_BF: np.ndarray = field(default_factory=lambda: np.eye(3))


@dataclass(frozen=True, eq=False)
class Marker:
    """A skin/brace marker fixed on a body.

    name : model name; label : the label in the trial file (defaults to name)
    p_BM : (3,) m position in the body frame; weight : relative weight (1/m² scale-free)
    """

    name: str
    body: str
    p_BM: np.ndarray
    weight: float = 1.0
    label: str = ""
