"""Benchmark of the knee contact example (examples/knee/knee_contact.yaml): FDK frames
per second of the planar knee with a quadriceps wrapping the condyle cylinder and
elastic-foundation contact between generated STL meshes (2 FDK DOFs, determinate
kinematics, 51 frames over a 90-degree flexion; ``--quick``: 11 frames). Model loading
and the distance-grid build are excluded; median of 3 runs after a 3-frame first call.
Target (issue 13): ``knee_example_contact_fdk_fps`` ≥ 200 frames/s."""

from __future__ import annotations

import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "knee"


def run(quick=False):
    import importlib.util

    from ..fdk.analysis import run_fdk
    from ..io.modelfile import load_model_and_settings

    if not (EXAMPLE / "knee_contact.yaml").is_file():
        return [{"name": "knee_example_contact_fdk_fps", "value": float("nan"), "unit": "frames/s",
                 "note": f"example not found at {EXAMPLE} (run from a source checkout)"}]
    spec = importlib.util.spec_from_file_location("knee_make_meshes", EXAMPLE / "make_meshes.py")
    make_meshes = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_meshes)
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        shutil.copy(EXAMPLE / "knee_contact.yaml", d / "knee_contact.yaml")
        make_meshes.write_meshes(d / "meshes")
        model, settings = load_model_and_settings(str(d / "knee_contact.yaml"))
        times = np.linspace(0.0, 1.0, 11 if quick else 51)
        run_fdk(model, None, times[:3], settings)  # first call: cached kernels loaded
        rates, conv = [], 0.0
        for _ in range(1 if quick else 3):
            t0 = time.perf_counter()
            res = run_fdk(model, None, times, settings)
            rates.append(len(times) / (time.perf_counter() - t0))
            conv = float(res.converged.mean())
    return [{"name": "knee_example_contact_fdk_fps", "value": statistics.median(rates), "unit": "frames/s",
             "convergence_rate": conv, "target": 200}]
