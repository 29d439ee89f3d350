"""Fuzz benchmark: mutated input files per second through the loaders
(:mod:`openfdk.bench.fuzz_inputs`), and the number of unexpected exceptions (must be 0).

Records:
* ``fuzz_inputs_per_s`` — mutated inputs of all kinds (:data:`~openfdk.bench.fuzz_inputs.KINDS`:
  model, subject and study files, C3D and TRC trials, OpenSim models, IK setups,
  ExternalLoads with their GRF files, motion files, force plates, result folders,
  checkpoints, study locks) loaded or refused per second (the run over its time);
* ``fuzz_<kind>_inputs_per_s`` — the same per file kind;
* ``fuzz_unexpected_exceptions`` — loader outcomes other than success or the
  documented error naming the file.
"""

from __future__ import annotations

from .fuzz_inputs import KINDS, Bases, fuzz


def run(quick=False):
    n = 25 if quick else 400
    bases = Bases(KINDS)
    records, total, seconds, unexpected = [], 0, 0.0, 0
    try:
        for kind in KINDS:
            fuzz(kind, 3, seed=12345, bases=bases)   # warm-up: imports, compiled kernels
            c = fuzz(kind, n, seed=0, bases=bases)
            total += c["inputs"]
            seconds += c["seconds"]
            unexpected += len(c["unexpected"])
            records.append({"name": f"fuzz_{kind}_inputs_per_s", "value": c["inputs"] / c["seconds"], "unit": "1/s"})
    finally:
        bases.close()
    records.insert(0, {"name": "fuzz_inputs_per_s", "value": total / seconds, "unit": "1/s"})
    records.append({"name": "fuzz_unexpected_exceptions", "value": float(unexpected), "unit": "count"})
    return records
