"""The way round an ellipsoid held from one FDK frame to the next (forces/wrap_ways.py).

A ligament from a ground point over an ellipsoid (quadrant free) to an arm body: with
the arm's anchor 0.1 mm above the ellipsoid's x–y plane the +z way round is the shorter,
2 mm below it the −z way. The independent reference is the same ligament over the same
ellipsoid with its side fixed (+z or −z: one way round only)."""

import numpy as np
import pytest

from openfdk.forces.elements import add_ligament, add_wrap_surface
from openfdk.forces.forceset import ForceElements
from openfdk.forces.wrap_ways import geodesic_rows, held_ways, hold_ways, release_ways, restore_ways, wrap_nodes
from openfdk.model.builder import ModelBuilder

AXES = [0.02, 0.035, 0.013]


def _ligament(side=None):
    b = ModelBuilder("ways", gravity=(0, 0, 0))
    b.add_body("arm", 1.0, [1, 1, 1])
    b.add_frame("ground", "o", [-0.05, 0.0, 0.0])
    b.add_frame("arm", "i", [0.05, 0.003, 0.0])
    add_wrap_surface(b, "ell", "ellipsoid", "ground", AXES, side)
    add_ligament(b, "lig", ["ground.o", "ell", "arm.i"], stiffness=2000.0, reference_strain=0.05)
    return b.build()


def _length(forces, model, dz):
    state = model.initial_state()
    state.p_WB[model.body("arm").index] = [0.0, 0.0, dz]
    return float(forces.generalized_forces(state, 0.0)[1]["ligaments"].length[0])


def test_a_held_way_round_is_kept_and_a_released_one_is_the_shorter():
    model = _ligament()
    forces = ForceElements(model)
    one_way = {s: (ForceElements(_ligament([0, 0, s])), _ligament([0, 0, s])) for s in (1, -1)}

    def way(dz, s):
        f, m = one_way[s]
        return _length(f, m, dz)

    assert way(1e-4, 1) < way(1e-4, -1) and way(-2e-3, -1) < way(-2e-3, 1) - 1e-3
    assert abs(_length(forces, model, 1e-4) - way(1e-4, 1)) < 1e-11  # alone: the shorter way
    hold_ways(forces)
    (nodes,) = wrap_nodes(forces)
    assert len(geodesic_rows(nodes)) == 1 and held_ways(forces)[0][0, 3] == 1.0
    held = _length(forces, model, -2e-3)
    assert abs(held - way(-2e-3, 1)) < 1e-11  # held: the +z way, 1 mm longer than the other
    saved = held_ways(forces)
    release_ways(forces)
    assert abs(_length(forces, model, -2e-3) - way(-2e-3, -1)) < 1e-11  # released: the shorter way
    restore_ways(forces, saved)
    assert abs(_length(forces, model, -2e-3) - way(-2e-3, 1)) < 1e-11  # a checkpoint's held way again


@pytest.mark.parametrize("saved", [None, [], [np.zeros((2, 4))], [np.full((1, 4), np.nan)]])
def test_a_checkpoint_with_other_ways_is_refused(saved):
    forces = ForceElements(_ligament())
    with pytest.raises(ValueError, match="held wrap ways"):
        restore_ways(forces, saved)
