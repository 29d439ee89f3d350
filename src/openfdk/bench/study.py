"""Benchmark: the mandible study's ligament parameter study (the paper's 15 FDK models:
whole-ligament stiffness 136.2 / 272.4 / 544.8 N/m × reference strain −0.04…0.04 step
0.02, docs/design.md §2, on the three tasks: 45 cases) on the virtual subject, run as an
openfdk.study study exactly as ``openfdk demo`` runs it
(:mod:`openfdk.mandible.parameter_study`). To keep the benchmark to a few minutes each
case analyses the first 300 frames (3 s) of its task instead of five cycles (433–1002 frames;
150 frames until FDK became twice as fast on 2026-12-01, which kept the per-case work and
the benchmark's duration about the same).

Each timing runs the study in a fresh Python process, so both sides pay their start-up
(imports, numba cache loading, reading the distance grids from the disk cache; for Dask
also the cluster and its worker processes); serial and 2-worker runs alternate, 3 times
each (medians; quick: once), with BLAS/OpenMP limited to one thread as in Dask's workers (a
multi-threaded BLAS on these small matrices is slower, and erratic when the other core
is busy):

* ``mandible_parameter_study_serial_s``: ``workers=0``, every case one after the other;
* ``mandible_parameter_study_2workers_s``: a 2-process LocalCluster (started and stopped inside);
* ``mandible_parameter_study_speedup``: their ratio (target >= 1.8 on 2 cores with the cluster
  started cold inside the timing, issue 12; the ceiling for 45 equal cases on 2 workers is
  45/23 = 1.96);
* ``mandible_parameter_study_2workers_warm_s`` / ``mandible_parameter_study_2workers_malloc_trim_warm_s``:
  the study on an already running, warmed-up 2-worker cluster without / with Dask's
  ``MALLOC_TRIM_THRESHOLD_=65536`` in the workers (docs/design.md §5; openfdk removes it).

The same study on whole five-cycle recordings (chewing 523, protrusion 1092, open–close
722 frames per case, the size of the demo's study: 433–1002 frames), 2 alternations
(serial and 2 workers cold, each in a fresh process as above; the means):

* ``mandible_parameter_study_whole_trials_serial_s`` / ``..._2workers_s`` / ``..._speedup``.

Since the target was set (serial 97 s with 150-frame cases) the engine became about six
times faster, so a 300-frame case now takes ≈ 0.5 s and the start-up that both runs pay
weighs six times more in the 300-frame figure (docs/studies.md "Speed"); the whole-trial
figures show the speed-up on cases of the size the demo runs.

Quick mode: coarse meshes, open–close only, 2 cases of 40 frames, no warm or whole-trial
variants.
"""

from __future__ import annotations

import dataclasses
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SINGLE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def write_inputs(d: Path, n_frames: int | None, quick: bool, cycles: int = 2) -> Path:
    """A virtual subject, its recordings of ``cycles`` cycles per task (quick: open–close
    only, 1 cycle), the mandible models and the parameter study over the first
    ``n_frames`` frames of each task (None: the whole recording), in ``d``. The study (a
    Study object: its cases carry the analysis window) is pickled to ``d/study.pkl``,
    whose path is returned."""
    from ..io.trials import recorded_duration_s
    from ..mandible.experiment import record_experiment
    from ..mandible.generator import create_subject
    from ..mandible.models import write_models
    from ..mandible.parameter_study import parameter_study
    from ..mandible.registration import register_braces
    from ..mandible.subject import load_subject

    subject_dir = create_subject(d / "subject", resolution="coarse" if quick else "default")
    tasks = ("open_close",) if quick else ("chewing", "protrusion", "open_close")
    record_experiment(subject_dir, tasks=tasks, cycles=1 if quick else cycles)
    subject = load_subject(subject_dir)
    reg = register_braces(subject, subject_dir / "trials" / "reference.c3d")
    models = write_models(subject, reg, d / "models")
    windows = {}
    for task in tasks:
        trial = subject_dir / "trials" / f"{task}.c3d"
        end = recorded_duration_s(trial) if n_frames is None else (n_frames - 1) / 100.0
        windows[task] = (trial, 0.0, end)
    study = parameter_study(models["fdk"], windows, quick=quick)
    from ..io.modelfile import load_model

    load_model(models["fdk"])  # the fossa distance grids into the disk cache, as after a first run
    return _save(study, d / "study.pkl")


def _save(study, path):
    Path(path).write_bytes(pickle.dumps(study))
    return Path(path)


def _load(path):
    return pickle.loads(Path(path).read_bytes())


def warm_process(study_path, out_dir):
    """Run a (small) pickled study in this process, e.g. in every worker through
    client.run."""
    from ..study.runner import run_study

    run_study(_load(study_path), Path(out_dir) / str(os.getpid()), workers=0, progress=False, force=True)


def _timed_in_fresh_process(study_path, out_dir, workers):
    """Wall time (s) of run_study in a new interpreter, and its counts."""
    code = ("import json, sys, time\n"
            "from openfdk.bench.study import _load\n"
            "from openfdk.study.runner import run_study\n"
            "if __name__ == '__main__':\n"
            "    t0 = time.perf_counter()\n"
            "    res = run_study(_load(sys.argv[1]), sys.argv[2], workers=int(sys.argv[3]), progress=False)\n"
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

    n_frames = 40 if quick else 300
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        study_path = write_inputs(d / "inputs", n_frames, quick)
        runs = {0: [], 2: []}
        for r in range(1 if quick else 3):
            for workers in (0, 2):
                runs[workers].append(_timed_in_fresh_process(study_path, d / f"out-{workers}-{r}", workers))
        serial, parallel = (sorted(runs[w], key=lambda x: x["wall_s"])[len(runs[w]) // 2] for w in (0, 2))  # medians
        out += [
            {"name": "mandible_parameter_study_cases", "value": serial["counts"]["cases"], "unit": "cases"},
            {"name": "mandible_parameter_study_frames_per_case", "value": n_frames, "unit": "frames"},
            {"name": "mandible_parameter_study_serial_s", "value": serial["wall_s"], "unit": "s"},
            {"name": "mandible_parameter_study_2workers_s", "value": parallel["wall_s"], "unit": "s"},
            {"name": "mandible_parameter_study_speedup", "value": serial["wall_s"] / parallel["wall_s"], "unit": "x"},
            {"name": "mandible_parameter_study_min_convergence_rate",
             "value": min(serial["convergence"] + parallel["convergence"]), "unit": "fraction"},
        ]
        if not quick:
            whole_path = write_inputs(d / "whole", None, quick, cycles=5)
            whole = {0: [], 2: []}
            for r in range(2):
                for workers in (0, 2):
                    whole[workers].append(_timed_in_fresh_process(whole_path, d / f"whole-{workers}-{r}", workers)["wall_s"])
            serial_s, parallel_s = (sum(whole[w]) / len(whole[w]) for w in (0, 2))
            out += [
                {"name": "mandible_parameter_study_whole_trials_serial_s", "value": serial_s, "unit": "s"},
                {"name": "mandible_parameter_study_whole_trials_2workers_s", "value": parallel_s, "unit": "s"},
                {"name": "mandible_parameter_study_whole_trials_speedup", "value": serial_s / parallel_s, "unit": "x"},
            ]
            study = _load(study_path)
            warm = _save(dataclasses.replace(study, cases=study.cases[:1]), d / "warm.pkl")
            for name, trim in (("mandible_parameter_study_2workers_warm_s", False),
                               ("mandible_parameter_study_2workers_malloc_trim_warm_s", True)):
                with dask_client(workers=2, malloc_trim=trim) as client:
                    client.run(warm_process, str(warm), str(d / "out-warm"))  # every worker
                    t0 = time.perf_counter()
                    run_study(study, d / f"out-{name}", client=client, progress=False)
                    out.append({"name": name, "value": time.perf_counter() - t0, "unit": "s"})
    return out


if __name__ == "__main__":  # pragma: no cover - manual runs: python -m openfdk.bench.study [--quick]
    for record in run(quick="--quick" in sys.argv):
        print(json.dumps(record), flush=True)
