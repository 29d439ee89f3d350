"""Benchmarks of the mandible study on the virtual subject: FDK and POP frames per second
on the open–close trial (FDK model: two condyle–fossa contacts with the generated
meshes, 3 FDK DOFs, 6 ligaments, 24 Hill muscles, marker tracking; model loading
excluded), and the wall time of the whole demo (``--quick``: the reduced demo)."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path


def run(quick=False):
    from ..jobs import load_trajectories
    from ..fdk.analysis import run_fdk
    from ..analysis.inverse_dynamics import run_inverse_dynamics
    from ..kinematics.analysis import run_tracking
    from ..model.modelfile import load_model
    from ..mandible.demo import run_demo
    from ..mandible.experiment import record_experiment
    from ..mandible.generator import create_subject
    from ..mandible.models import write_models
    from ..mandible.registration import register_braces
    from ..mandible.subject import load_subject

    out = []
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        create_subject(d / "subject", resolution="coarse" if quick else "default")
        record_experiment(d / "subject", tasks=("open_close",), cycles=1 if quick else 3)
        subject = load_subject(d / "subject")
        reg = register_braces(subject, d / "subject" / "trials" / "reference.c3d")
        paths = write_models(subject, reg, d / "models")
        trial = d / "subject" / "trials" / "open_close.c3d"
        for kind in ("fdk", "pop"):
            model = load_model(paths[kind])
            _, traj = load_trajectories(model, trial)
            times = traj.time[: (60 if quick else 400)]
            t0 = time.perf_counter()
            if kind == "fdk":
                res = run_fdk(model, traj, times)
                conv = float(res.converged.mean())
            else:
                kin = run_tracking(model, traj, times)
                conv = float(run_inverse_dynamics(model, kin).converged.mean())
            fps = len(times) / (time.perf_counter() - t0)
            out.append({"name": f"mandible_{kind}_fps", "value": fps, "unit": "frames/s", "convergence_rate": conv})
        t0 = time.perf_counter()
        run_demo(d / "demo", quick=quick, progress=False, log=lambda *a, **k: None)
        out.append({"name": "demo_quick_wall_s" if quick else "demo_wall_s", "value": time.perf_counter() - t0, "unit": "s"})
    return out
