"""Benchmark: FDK on the two-sided TMJ-like test model (two condyle–fossa contacts,
3 FDK DOFs, 6 ligaments, 24 Hill muscles, marker tracking of an open–close at 100 Hz
with 0.1 mm noise): mean residual evaluations per frame (each a kinematic analysis and
a recruitment solve), Jacobians per frame and frames per second, for the analytic and
the central-difference Jacobian, each with the default Broyden-updated Jacobian reuse
(``fdk_tmj_<jacobian>_*``) and with a fresh Jacobian every iteration as in the paper
(``fdk_tmj_<jacobian>_fresh_*``). Medians over repeats; model loading (distance grids) and compilation excluded. Frames per
second are per CPU second of the process (``time.process_time``; the analysis is
single-threaded, so this is the one-core rate, robust on a machine shared with other
jobs)."""

from __future__ import annotations

import statistics
import tempfile
import time


def run(quick=False):
    from ..fdk.analysis import run_fdk
    from ..io.c3d import MarkerTrial
    from ..io.markers import MarkerTrajectories
    from ..io.modelfile import model_and_settings_from_dict
    from ..fixtures.synthetic_jaw import jaw_fdk_model_dict, jaw_markers, write_jaw_meshes

    n_frames = 40 if quick else 300
    repeats = 1 if quick else 3
    with tempfile.TemporaryDirectory() as d:
        write_jaw_meshes(d)
        model, settings = model_and_settings_from_dict(jaw_fdk_model_dict(d), "tmj_fdk.yaml", base_dir="/")
    t, labels, x, _ = jaw_markers(n_frames, noise=1e-4, seed=5)
    traj = MarkerTrajectories(MarkerTrial(tuple(labels), 100.0, t, x, "synthetic"), cutoff_hz=8.0)
    out = []
    for jac in ("analytic", "central"):
        run_fdk(model, traj, t[:5], settings, jacobian=jac)  # warm-up
        for reuse in (True, False):
            rates, evals, jacs, conv = [], [], [], []
            for _ in range(repeats if jac == "analytic" else 1):
                t0 = time.process_time()
                res = run_fdk(model, traj, t, settings, jacobian=jac, reuse_jacobian=reuse)
                rates.append(n_frames / (time.process_time() - t0))
                evals.append(res.evaluations.mean())
                jacs.append(res.jacobians.mean())
                conv.append(res.converged.mean())
            tag = f"fdk_tmj_{jac}" + ("" if reuse else "_fresh")
            out += [
                {"name": f"{tag}_fps", "value": statistics.median(rates), "unit": "frames/s"},
                {"name": f"{tag}_evaluations_per_frame", "value": statistics.median(evals), "unit": "evaluations"},
                {"name": f"{tag}_jacobians_per_frame", "value": statistics.median(jacs), "unit": "jacobians"},
                {"name": f"{tag}_convergence_rate", "value": min(conv), "unit": "fraction"},
            ]
    return out
