"""Benchmark: the paper's 15-model TMJ ligament parameter study (whole-ligament stiffness
136.2 / 272.4 / 544.8 N/m split over 3 elements × reference strain −0.04…0.04 step 0.02,
DESIGN.md §2) on the synthetic TMJ-like FDK model (stand-in for the mandible models until
they land), one 300-frame open–close trial at 100 Hz, run as a study:

* ``study_param15_serial_s``: every case one after the other in this process (warmed up
  first: numba kernels loaded, distance grids built);
* ``study_param15_2workers_s``: a 2-process LocalCluster, wall time including starting
  the cluster and the workers' own warm-up (imports, numba, grids) — what a user waits;
* ``study_param15_speedup``: their ratio (target >= 1.7 on 2 cores);
* ``study_param15_2workers_warm_s``: the same study again on the running cluster;
* ``study_param15_2workers_malloc_trim_s``: on a running cluster whose workers keep
  Dask's MALLOC_TRIM_THRESHOLD_=65536 (DESIGN.md §5; openfdk removes it by default).

Quick mode: 4 cases of 30 frames, no warm/malloc-trim variants.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

STIFFNESS = [136.2, 272.4, 544.8]  # N/m, whole ligament (paper)
REFERENCE_STRAIN = [-0.04, -0.02, 0.0, 0.02, 0.04]


def _write_inputs(d: Path, n_frames: int, grid: dict):
    import yaml

    from ..io.c3d import write_c3d
    from ..synthetic_jaw import jaw_fdk_model_dict, jaw_markers, write_jaw_meshes

    write_jaw_meshes(d / "meshes")
    (d / "tmj.yaml").write_text(yaml.safe_dump(jaw_fdk_model_dict("meshes"), sort_keys=False))
    t, labels, x, _ = jaw_markers(n_frames, noise=1e-4, seed=5)
    write_c3d(d / "trial.c3d", labels, x, 100.0)
    study = {
        "openfdk_study": 1, "name": "param15", "models": {"tmj": "tmj.yaml"}, "trials": {"open_close": "trial.c3d"},
        "parameters": {"stiffness": {"set": "ligaments.tmj_ligament_*.stiffness", "scale": 1 / 3},
                       "reference_strain": "ligaments.tmj_ligament_*.reference_strain"},
        "grid": grid,
    }
    (d / "study.yaml").write_text(yaml.safe_dump(study, sort_keys=False))
    return d / "study.yaml"


def _warm_process(study_path, out_dir):
    """Run the small warm-up study in this process (a worker, via client.run)."""
    import os

    from ..study.runner import run_study

    run_study(study_path, Path(out_dir) / str(os.getpid()), workers=0, progress=False, force=True)


def run(quick=False):
    from ..study.cluster import dask_client
    from ..study.runner import run_study
    from ..study.spec import load_study

    n_frames = 30 if quick else 300
    grid = ({"stiffness": STIFFNESS[:2], "reference_strain": REFERENCE_STRAIN[:2]} if quick
            else {"stiffness": STIFFNESS, "reference_strain": REFERENCE_STRAIN})
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        study = load_study(_write_inputs(d, n_frames, grid))
        n_cases = len(study.cases)
        # warm-up of this process on a short study (same model, 5 frames)
        warm = _write_inputs(d / "warm", 5, {"stiffness": [272.4]})
        _warm_process(warm, d / "out-warm")

        t0 = time.perf_counter()
        serial = run_study(study, d / "out-serial", workers=0, progress=False)
        t_serial = time.perf_counter() - t0
        t0 = time.perf_counter()
        parallel = run_study(study, d / "out-2", workers=2, progress=False)
        t_parallel = time.perf_counter() - t0
        for res in (serial, parallel):
            if not res.ok:
                raise RuntimeError(f"benchmark study had failed cases: {[r['error'] for r in res.failed]}")
        conv = min(r["metrics"]["convergence_rate"] for r in serial.records + parallel.records)
        out += [
            {"name": "study_param15_cases", "value": n_cases, "unit": "cases"},
            {"name": "study_param15_frames_per_case", "value": n_frames, "unit": "frames"},
            {"name": "study_param15_serial_s", "value": t_serial, "unit": "s"},
            {"name": "study_param15_2workers_s", "value": t_parallel, "unit": "s"},
            {"name": "study_param15_speedup", "value": t_serial / t_parallel, "unit": "x"},
            {"name": "study_param15_min_convergence_rate", "value": conv, "unit": "fraction"},
        ]
        if not quick:
            for name, trim in (("study_param15_2workers_warm_s", False), ("study_param15_2workers_malloc_trim_s", True)):
                with dask_client(workers=2, malloc_trim=trim) as client:
                    client.run(_warm_process, str(warm), str(d / "out-warm"))  # every worker
                    t0 = time.perf_counter()
                    run_study(study, d / f"out-{name}", client=client, progress=False)
                    out.append({"name": name, "value": time.perf_counter() - t0, "unit": "s"})
    return out
