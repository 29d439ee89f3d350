"""The mandible force benchmarks (issue 28) from a study result: Table 2's smallest and
largest row RMSD and the share of feasible frames over every task and both models,
on a hand-made result whose answers are known."""

from openfdk.bench.mandible import force_records


def _run(frames, converged, failed_spans=()):
    return {"frames": frames, "forces_converged": converged,
            "failed_frames": {"frames": frames - converged, "spans_s": [list(s) for s in failed_spans],
                              "incisal_opening_mm": [42.0, 45.0] if frames > converged else None}}


def test_force_records_from_a_known_result():
    """Rows with RMSD 0.8, 19.6 and 3.0 N: min 0.8, max 19.6. Frames: chewing 400 + 400,
    open–close 600 POP (480 feasible) + 600 FDK; a failed task does not count:
    (400 + 400 + 480 + 600) / 2000 = 0.94; the failed POP frames are listed."""
    table2 = [{"task": "chewing", "side": "left", "direction": "AP", "POP_RMSD_mean": 0.8},
              {"task": "open_close", "side": "right", "direction": "AP", "POP_RMSD_mean": 19.6},
              {"task": "open_close", "side": "right", "direction": "SI", "POP_RMSD_mean": 3.0}]
    summary = {"completed": ["chewing", "open_close"],
               "runs": {"chewing": {"POP": _run(400, 400), "FDK": _run(400, 400)},
                        "open_close": {"POP": _run(600, 480, [(1.2, 1.5)]), "FDK": _run(600, 600)},
                        "parameter_study": {"cases": 2}}}
    records = {r["name"]: r for r in force_records({"summary": summary, "table2": table2})}
    assert records["mandible_table2_rmsd_min_N"]["value"] == 0.8
    assert records["mandible_table2_rmsd_max_N"]["value"] == 19.6
    share = records["mandible_realistic_feasible_share"]
    assert share["value"] == (400 + 400 + 480 + 600) / 2000
    assert share["frames"] == 2000 and list(share["failed_frames"]) == ["open_close/POP"]
    assert all(r["unit"] in ("N", "") for r in records.values())
