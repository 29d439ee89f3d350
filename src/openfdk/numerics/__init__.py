"""Numerical building blocks with no model in them: rotations and Euler parameters
(:mod:`.spatial`), the not-a-knot cubic spline (:mod:`.cubic_spline`) and finite
differences on the manifold of body poses (:mod:`.numdiff`)."""
