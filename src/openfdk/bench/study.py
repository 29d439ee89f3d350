"""Benchmark: the paper's 15-model TMJ ligament parameter study (whole-ligament stiffness
136.2 / 272.4 / 544.8 N/m split over 3 elements × reference strain −0.04…0.04 step 0.02,
DESIGN.md §2) on the synthetic TMJ-like FDK model (the stand-in until the mandible
models land), one 300-frame open–close trial at 100 Hz, run as a study.

Each timing runs ``run_study`` in a fresh Python process, so both sides pay their
start-up (imports, numba cache loading, distance grids; for Dask also the cluster and
its worker processes), with BLAS/OpenMP limited to one thread as in Dask's workers (a
multi-threaded BLAS on these small matrices is slower, and erratic when the other core
is busy):

* ``study_param15_serial_s``: ``workers=0``, every case one after the other;
* ``study_param15_2workers_s``: a 2-process LocalCluster (started and stopped inside);
* ``study_param15_speedup``: their ratio (target >= 1.7 on 2 cores);
* ``study_param15_2workers_warm_s`` / ``study_param15_2workers_malloc_trim_warm_s``:
  the study on an already running, warmed-up 2-worker cluster without / with Dask's
  ``MALLOC_TRIM_THRESHOLD_=65536`` in the workers (DESIGN.md §5; openfdk removes it).

Quick mode: 4 cases of 30 frames, no warm variants.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

STIFFNESS = [136.2, 272.4, 544.8]  # N/m, whole ligament (paper)
REFERENCE_STRAIN = [-0.04, -0.02, 0.0, 0.02, 0.04]
SINGLE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def write_inputs(d: Path, n_frames: int, grid: dict) -> Path:
    """Meshes, the TMJ-like model, a trial of n_frames and a study file over ``grid`` in
    ``d``. Returns the study file."""
    import yaml

    from ..io.c3d import write_c3d
    from ..synthetic_jaw import jaw_fdk_model_dict, jaw_markers, write_jaw_meshes

    d.mkdir(parents=True, exist_ok=True)
    write_jaw_meshes(d / "meshes")
    (d / "tmj.yaml").write_text(yaml.safe_dump(jaw_fdk_model_dict("meshes"), sort_keys=False))
    _t, labels, x, _ = jaw_markers(n_frames, noise=1e-4, seed=5)
    write_c3d(d / "trial.c3d", labels, x, 100.0)
    study = {
        "openfdk_study": 1, "name": "param15", "models": {"tmj": "tmj.yaml"}, "trials": {"open_close": "trial.c3d"},
        "parameters": {"stiffness": {"set": "ligaments.tmj_ligament_*.stiffness", "scale": 1 / 3},
                       "reference_strain": "ligaments.tmj_ligament_*.reference_strain"},
        "grid": grid,
    }
    (d / "study.yaml").write_text(yaml.safe_dump(study, sort_keys=False))
    return d / "study.yaml"


def warm_process(study_path, out_dir):
    """Run a (small) study in this process, e.g. in every worker through client.run."""
    from ..study.runner import run_study

    run_study(study_path, Path(out_dir) / str(os.getpid()), workers=0, progress=False, force=True)


def _timed_in_fresh_process(study_path, out_dir, workers):
    """Wall time (s) of run_study in a new interpreter, and its counts."""
    code = ("import json, sys, time\n"
            "from openfdk.study.runner import run_study\n"
            "if __name__ == '__main__':\n"
            "    t0 = time.perf_counter()\n"
            "    res = run_study(sys.argv[1], sys.argv[2], workers=int(sys.argv[3]), progress=False)\n"
            "    print(json.dumps({'wall_s': time.perf_counter() - t0, 'counts': res.summary['counts'],\n"
            "                      'convergence': [r['metrics']['convergence_rate'] for r in res.records\n"
            "                                      if r['status'] == 'completed']}))\n")
    script = Path(out_dir).parent / "timed_study.py"
    script.write_text(code)
    env = {**os.environ, **SINGLE_THREAD}
    proc = subprocess.run([sys.executable, str(script), str(study_path), str(out_dir), str(workers)],
                          capture_output=True, text=True, env=env, timeout=3600, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"timed study (workers={workers}) failed: {proc.stderr.strip()[-2000:]}")
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    if result["counts"]["failed"]:
        raise RuntimeError(f"timed study (workers={workers}) had failed cases: {result['counts']}")
    return result


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
        study_path = write_inputs(d / "inputs", n_frames, grid)
        serial = _timed_in_fresh_process(study_path, d / "out-serial", 0)
        parallel = _timed_in_fresh_process(study_path, d / "out-2workers", 2)
        out += [
            {"name": "study_param15_cases", "value": serial["counts"]["cases"], "unit": "cases"},
            {"name": "study_param15_frames_per_case", "value": n_frames, "unit": "frames"},
            {"name": "study_param15_serial_s", "value": serial["wall_s"], "unit": "s"},
            {"name": "study_param15_2workers_s", "value": parallel["wall_s"], "unit": "s"},
            {"name": "study_param15_speedup", "value": serial["wall_s"] / parallel["wall_s"], "unit": "x"},
            {"name": "study_param15_min_convergence_rate",
             "value": min(serial["convergence"] + parallel["convergence"]), "unit": "fraction"},
        ]
        if not quick:
            warm = write_inputs(d / "warm", 5, {"stiffness": [272.4]})
            study = load_study(study_path)
            for name, trim in (("study_param15_2workers_warm_s", False),
                               ("study_param15_2workers_malloc_trim_warm_s", True)):
                with dask_client(workers=2, malloc_trim=trim) as client:
                    client.run(warm_process, str(warm), str(d / "out-warm"))  # every worker
                    t0 = time.perf_counter()
                    run_study(study, d / f"out-{name}", client=client, progress=False)
                    out.append({"name": name, "value": time.perf_counter() - t0, "unit": "s"})
    return out


if __name__ == "__main__":  # pragma: no cover - manual runs: python -m openfdk.bench.study [--quick]
    for record in run(quick="--quick" in sys.argv):
        print(json.dumps(record), flush=True)
