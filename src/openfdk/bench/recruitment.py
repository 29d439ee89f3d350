"""Benchmark of the muscle recruitment solvers (paper Eq. 11).

Problem: Newton–Euler equilibrium of one rigid body (6 rows: 3 force rows in N, 3 moment
rows about the centre of mass in N·m) with

* 24 muscles, strengths 20–300 N, inserting at random points within ±3 cm of the centre
  of mass and pulling towards random origins 4–10 cm away;
* 8 reaction columns: 5 unilateral contact reactions (compression along a random normal at
  a random joint point, 20 kN strength, bounded like muscles — the paper's TMJ elements)
  and 3 free forces (an FDK residual force at a joint point along x, y, z).

The brief suggested 2 unilateral + 6 free reactions, but with 6 independent free columns
on 6 rows the free forces balance everything and the optimum is f_B = 0 (a trivial
problem); 5 + 3 keeps 32 unknowns with 3 rows left for the muscles.

d is built from a random admissible force set (activities up to ``load``) so every
problem is feasible. Timings include the Python call; numba compilation is excluded.
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["random_body_problem", "run"]


def _force_column(p_BP, u_B):
    """Column [u; p × u] of a unit force u (3,) applied at body point p (3,) m."""
    return np.concatenate([u_B, np.cross(p_BP, u_B)])


def random_body_problem(rng, n_muscles=24, n_unilateral=5, n_free=3, load=0.3,
                        weak_muscles=0):
    """A random feasible recruitment problem for one body.

    Parameters
    ----------
    rng : numpy Generator; n_muscles, n_unilateral, n_free : column counts
    (n_free ≤ 3: residual forces along x, y, z at one joint point);
    load : maximal activity f/s of the admissible force set that defines d;
    weak_muscles : number of muscles made weak (1–5 N) and loaded to full strength, so
    that upper bounds become active at the optimum.

    Returns
    -------
    C : (6, n) with n = n_muscles + n_unilateral + n_free; d : (6,) N / N·m;
    n_bounded : int; s : (n_bounded,) N.
    """
    columns = []
    strengths = []
    for _ in range(n_muscles):
        p_insertion = rng.uniform(-0.03, 0.03, 3)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        p_origin = p_insertion + rng.uniform(0.04, 0.10) * direction
        u = p_origin - p_insertion
        columns.append(_force_column(p_insertion, u / np.linalg.norm(u)))
        strengths.append(rng.uniform(20.0, 300.0))
    for _ in range(n_unilateral):
        p_contact = rng.uniform(-0.05, 0.05, 3)
        normal = rng.normal(size=3)
        columns.append(_force_column(p_contact, normal / np.linalg.norm(normal)))
        strengths.append(20_000.0)
    p_joint = rng.uniform(-0.05, 0.05, 3)
    for k in range(n_free):
        columns.append(_force_column(p_joint, np.eye(3)[k]))
    C = np.array(columns).T
    s = np.array(strengths)
    n_bounded = n_muscles + n_unilateral
    activity = rng.uniform(0.0, load, n_bounded)
    activity[n_muscles:] *= 0.01  # contact reactions carry a few hundred N at most
    weak = rng.choice(n_muscles, size=weak_muscles, replace=False)
    s[weak] = rng.uniform(1.0, 5.0, weak_muscles)
    activity[weak] = 1.0
    f_admissible = np.concatenate([activity * s, rng.normal(0.0, 50.0, n_free)])
    d = C @ f_admissible
    return C, d, n_bounded, s


def _median_ms(solve, problems, repeats):
    times = []
    for k in range(repeats):
        C, d, n_bounded, s = problems[k % len(problems)]
        t0 = time.perf_counter()
        result = solve(C, d, n_bounded, s)
        times.append(time.perf_counter() - t0)
        if not result.converged:
            raise RuntimeError(f"benchmark problem {k} did not converge: {result.message}")
    return 1e3 * float(np.median(times))


def run(quick: bool) -> list[dict]:
    """Median solve times (ms) of each criterion on the 24-muscle, 8-reaction body problem.

    quick : fewer repeats (50 instead of 400). Returns records {"name", "value", "unit"}.
    """
    from openfdk.recruitment import solve_minmax, solve_polynomial, solve_quadratic_daqp

    rng = np.random.default_rng(20170101)
    problems = [random_body_problem(rng) for _ in range(50)]
    repeats = 50 if quick else 400

    solvers = {
        "recruitment_polynomial_p3_24m8r_ms": lambda C, d, n, s: solve_polynomial(C, d, n, s, 3.0),
        "recruitment_polynomial_p2_24m8r_ms": lambda C, d, n, s: solve_polynomial(C, d, n, s, 2.0),
        "recruitment_quadratic_daqp_24m8r_ms": solve_quadratic_daqp,
        "recruitment_minmax_24m8r_ms": solve_minmax,
    }
    records = []
    for name, solve in solvers.items():
        solve(*problems[0])  # compile / warm up, excluded from timing
        records.append({"name": name, "value": _median_ms(solve, problems, repeats),
                        "unit": "ms"})

    # warm start: a slowly varying sequence of frames (load changes by 1 % per frame)
    C, d, n_bounded, s = problems[0]
    previous = solve_polynomial(C, d, n_bounded, s, 3.0)
    times = []
    for k in range(repeats):
        d_k = d * (1.0 + 0.3 * np.sin(0.01 * k))
        t0 = time.perf_counter()
        previous = solve_polynomial(C, d_k, n_bounded, s, 3.0, x0=previous)
        times.append(time.perf_counter() - t0)
    records.append({"name": "recruitment_polynomial_p3_24m8r_warm_ms",
                    "value": 1e3 * float(np.median(times)), "unit": "ms"})
    return records
