"""The measured loads' samples (forces/data_loads.py): a time not prepared is sampled once
and kept while the same time is asked again (FDK evaluates one frame's residual 3–5
times), and asked anew at another time."""

import numpy as np

from openfdk.forces.data_loads import DataLoad, DataLoadForces
from openfdk.model.timefunctions import Constant, SplineThroughData, TimeFunction


class Counted(TimeFunction):
    """A time function that counts its evaluations (the spline it wraps gives the values)."""

    def __init__(self, inner):
        self.inner, self.calls = inner, 0

    def derivatives(self, t):
        self.calls += 1
        return self.inner.derivatives(t)


def test_a_time_is_sampled_once_while_it_is_asked_again_and_anew_at_another():
    t_data = np.linspace(0.0, 1.0, 21)
    F = np.column_stack([np.sin(3 * t_data), np.cos(2 * t_data), t_data ** 2]) * 100.0  # N
    force = Counted(SplineThroughData(t_data, F))
    zero = Constant([0.0, 0.0, 0.0])
    loads = DataLoadForces([DataLoad("plate", 1, force, zero, zero)])
    column = np.array([-1, 0])  # body 0 fixed, body 1 moving
    expected = {t: force.inner.derivatives(t)[0] for t in (0.31, 0.47)}
    asked = (0.31, 0.31, 0.31, 0.47, 0.47, 0.31)
    for t in asked:
        S = loads._sampled(t, column)
        assert np.array_equal(S[0, :3], expected[t]) and not np.any(S[0, 3:])
    # one spline evaluation per change of time: 0.31, 0.47, 0.31 again
    assert force.calls == 3
    # a prepared time is read from the table, not sampled
    loads.prepare(np.array([0.5, 0.6]))
    before = force.calls
    assert np.allclose(loads._sampled(0.5, column)[0, :3], force.inner.derivatives(0.5)[0], rtol=1e-14, atol=1e-12)
    assert force.calls == before  # read from the table
