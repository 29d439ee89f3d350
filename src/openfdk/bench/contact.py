"""Contact benchmark: a condyle-like cap against a fossa-like surface.

Geometry (generated, :mod:`openfdk.contact.shapes`): half ellipsoid 9 mm (AP) × 20 mm (ML)
× 4 mm high, ≈ 4 900 vertices, on a mandible whose centre of mass is 40 mm away; a
fossa-like roof with an articular eminence, ≈ 10 000 triangles. The condyle top is
pressed 0.2 mm into the fossa roof (≈ 700 vertices in contact, ≈ 65 N).

Records (medians over repeats):
* ``contact_grid_eval_ms`` — one :meth:`ElasticFoundation.evaluate` in grid mode
  (target ≤ 0.2 ms);
* ``contact_grid_eval_stiffness_ms`` — the same with the 12×12 stiffness;
* ``contact_exact_eval_ms`` — exact mode (libigl AABB closest points);
* ``contact_grid_build_s`` — building the distance grid of the fossa at the default
  spacing and band (uncached).

Implant-sized records (:func:`implant_like_pair`: a femoral-condyle-like sphere cap of
≈ 50 000 triangles, R = 30 mm, against a conforming dish of ≈ 6 500 vertices, 0.2 mm into it (≈ 5 700 in contact),
at the OpenSim import's grid spacing 0.5 mm and the default 3 mm band):
* ``contact_grid_build_s_50k`` — building that grid (uncached; target ≤ 1 s);
* ``contact_eval_us_50k`` — one grid-mode evaluation of the pair (target ≤ 1000 µs).
"""

from __future__ import annotations


import numpy as np

from openfdk.bench.timing import timed_runs

from openfdk.contact import (
    DEFAULT_GRID_SPACING,
    DEFAULT_MAX_DEPTH,
    ElasticFoundation,
    surface_mesh,
)
from openfdk.contact.distance_grid import build_distance_grid
from openfdk.contact.shapes import ellipsoid_cap, flat_patch, fossa_surface, sphere_cap

PRESSURE_MODULUS = 10e9  # N/m³ (paper)


def _median_time(fun, repeats):
    """Median wall time (s) of ``repeats`` calls of ``fun``."""
    return float(np.median(timed_runs(fun, repeats)[1]))


def tmj_like_pair():
    """(condyle SurfaceMesh in the mandible frame, fossa SurfaceMesh, contact pose).

    The pose is (r_Wa, R_Wa, r_Wb, R_Wb) with the skull (b) at the world origin.
    """
    cap = ellipsoid_cap((4.5e-3, 10e-3, 4e-3), 0.29e-3)
    s0 = np.array([-0.01, 0.03, -0.025])  # condyle base centre from the mandible COM, m
    condyle = surface_mesh(cap.vertices_B + s0, cap.faces, name="condyle (generated)",
                           repair=False)
    fossa = fossa_surface(edge_length=0.38e-3, ml_radius=35e-3, name="fossa (generated)")
    top_in_b = np.array([0.5e-3, 0.0, -4e-3 + 0.2e-3])  # 0.2 mm into the roof
    pose = (top_in_b - s0, np.eye(3), np.zeros(3), np.eye(3))
    return condyle, fossa, pose


def implant_like_pair():
    """(dish SurfaceMesh of the vertices, condyle-like cap of ≈ 50k triangles, pose), m.

    The cap (body b, at the world origin) is a sphere of R = 30 mm, 50° around its pole
    −z, normals outward; the dish (body a) a cup of R = 31 mm, 35° around the same pole,
    normals inward, raised so that its bottom is 0.2 mm inside the cap's lowest point
    (R = 31 mm around R = 30 mm: the dish's vertices press into the cap near the pole).
    """
    cap = sphere_cap(30e-3, np.radians(50), 0.3e-3, name="condyle-like cap (generated)")
    dish = sphere_cap(31e-3, np.radians(35), 0.45e-3, inward=True, name="dish (generated)")
    # the dish's lowest point −31 mm + z0 sits 0.2 mm above the cap's −30 mm: z0 = 1.2 mm
    pose = (np.array([0.0, 0.0, 1.2e-3]), np.eye(3), np.zeros(3), np.eye(3))
    return dish, cap, pose


def run(quick: bool) -> list[dict]:
    """Run the contact benchmark; ``quick`` uses fewer repeats. Returns records."""
    # compile the numba kernels outside the timings
    tiny = flat_patch(2e-3, 2e-3, 1e-3)
    warm = ElasticFoundation(tiny, tiny, PRESSURE_MODULUS, mode="grid", grid_spacing=0.5e-3,
                             max_depth=1e-3)
    warm.evaluate(np.zeros(3), np.eye(3), np.zeros(3), np.eye(3), want_stiffness=True)

    condyle, fossa, pose = tmj_like_pair()
    records = []

    t_build = _median_time(
        lambda: build_distance_grid(fossa, DEFAULT_GRID_SPACING, DEFAULT_MAX_DEPTH),
        1 if quick else 3,
    )
    grid = ElasticFoundation(condyle, fossa, PRESSURE_MODULUS, mode="grid")
    exact = ElasticFoundation(condyle, fossa, PRESSURE_MODULUS, mode="exact")
    result = grid.evaluate(*pose)
    detail = (f"{condyle.n_vertices} vertices vs {fossa.n_faces} triangles, "
              f"{result.n_contact} in contact, |F| = {np.linalg.norm(result.force_W):.1f} N")
    n_eval = 200 if quick else 2000
    for _ in range(20):
        grid.evaluate(*pose, want_stiffness=True)
    t_grid = _median_time(lambda: grid.evaluate(*pose), n_eval)
    t_grid_k = _median_time(lambda: grid.evaluate(*pose, want_stiffness=True), n_eval)
    exact.evaluate(*pose)
    t_exact = _median_time(lambda: exact.evaluate(*pose), 5 if quick else 30)

    records.append({"name": "contact_grid_eval_ms", "value": 1e3 * t_grid, "unit": "ms",
                    "target": 0.2, "detail": detail})
    records.append({"name": "contact_grid_eval_stiffness_ms", "value": 1e3 * t_grid_k,
                    "unit": "ms", "detail": detail})
    records.append({"name": "contact_exact_eval_ms", "value": 1e3 * t_exact, "unit": "ms",
                    "detail": detail})
    records.append({"name": "contact_grid_build_s", "value": t_build, "unit": "s",
                    "detail": (f"spacing {DEFAULT_GRID_SPACING * 1e3:g} mm, max_depth "
                               f"{DEFAULT_MAX_DEPTH * 1e3:g} mm, {grid.grid.n_evaluated} "
                               f"nodes evaluated, {grid.grid.nbytes / 1e6:.1f} MB")})
    records += _implant_records(quick)
    return records


def _implant_records(quick):
    """``contact_grid_build_s_50k`` and ``contact_eval_us_50k`` (module docstring)."""
    dish, cap, pose = implant_like_pair()
    spacing = 0.5e-3  # openfdk.io.opensim.to_model.IMPORT_GRID_SPACING_M
    t_build = _median_time(lambda: build_distance_grid(cap, spacing, DEFAULT_MAX_DEPTH), 1 if quick else 3)
    pair = ElasticFoundation(dish, cap, PRESSURE_MODULUS, mode="grid", grid_spacing=spacing)
    result = pair.evaluate(*pose)
    for _ in range(20):
        pair.evaluate(*pose)
    t_eval = _median_time(lambda: pair.evaluate(*pose), 200 if quick else 2000)
    detail = (f"{dish.n_vertices} vertices vs {cap.n_faces} triangles, spacing {spacing * 1e3:g} mm, max_depth "
              f"{DEFAULT_MAX_DEPTH * 1e3:g} mm, {result.n_contact} in contact, "
              f"|F| = {np.linalg.norm(result.force_W):.0f} N")
    return [{"name": "contact_grid_build_s_50k", "value": t_build, "unit": "s", "target": 1.0,
             "detail": f"{detail}, {pair.grid.n_evaluated} nodes evaluated"},
            {"name": "contact_eval_us_50k", "value": 1e6 * t_eval, "unit": "us", "target": 1000.0,
             "detail": detail}]


if __name__ == "__main__":  # pragma: no cover
    for record in run(quick=False):
        print(record)
