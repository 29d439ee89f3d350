"""Force plates of C3D files written by other systems: ezc3d's sample files
(github pyomeca/ezc3d-testFiles, not part of the project).  Skipped unless
``OPENFDK_C3D_SAMPLES`` names a folder holding them; docs/force-plates.md quotes the figures.

Each vendor's channel sign is read from the data (openfdk.io.force_plates._push_sign).
The oracle is ezc3d's own extraction, which takes the channels as they are: for the
files that hold the force on the subject its force and centre of pressure are openfdk's,
for Kistler's BioWare (the action) its force is the negative.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

ezc3d = pytest.importorskip("ezc3d")

from openfdk.io.c3d import C3DError, read_c3d  # noqa: E402
from openfdk.io.force_plates import read_force_plates  # noqa: E402

FOLDER = Path(os.environ.get("OPENFDK_C3D_SAMPLES", "/nonexistent"))
pytestmark = pytest.mark.skipif(not (FOLDER / "BTS.c3d").is_file(),
                                reason="OPENFDK_C3D_SAMPLES does not hold ezc3d's sample files")

#: file: {plate: (holds the force on the subject, peak plate-normal push N)}; None: never loaded
LOADED = {
    "BTS.c3d": {"FP1": (True, 662), "FP2": None, "FP3": None, "FP4": (True, 637), "FP5": (True, 590),
                "FP6": None},
    "Qualisys.c3d": {"FP1": (True, 808), "FP2": (True, 840)},
    "FP_Type3.c3d": {"FP1": (True, 887), "FP2": None},
    "Kistler.c3d": {"FP1": (False, 816), "FP2": (False, 825)},
}


def _read(name):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plates = read_force_plates(FOLDER / name, cutoff_hz=0, rate="analog")
    return plates, [str(w.message) for w in caught]


@pytest.mark.parametrize("name", sorted(LOADED))
def test_each_vendor_sign_and_ezc3d(name):
    plates, caught = _read(name)
    assert not caught
    assert {p.name: None if p.never_loaded else (any("force on the subject" in n for n in p.notes),
                                                  round(float(np.max(-p.force @ p.rotation[:, 2]))))
            for p in plates} == LOADED[name]
    theirs = ezc3d.c3d(str(FOLDER / name), extract_forceplat_data=True)["data"]["platform"]
    for plate, platform in zip(plates, theirs):
        if plate.never_loaded:
            continue
        subject = any("force on the subject" in n for n in plate.notes)
        force = platform["force"].T * (1.0 if subject else -1.0)
        on = -plate.force @ plate.rotation[:, 2] > 200.0
        cop = platform["center_of_pressure"].T[on] * 1e-3            # mm in each file
        error_f = np.abs(plate.force - force).max() / np.abs(force).max()
        error_cop = np.abs(plate.cop[on] - cop).max()
        if name == "Kistler.c3d":     # openfdk subtracts the ZERO baseline (1-2 N), ezc3d not
            assert error_f < 2e-3 and error_cop < 2e-3
        elif name == "FP_Type3.c3d":  # corners 1.4 mm off a plane: the frames differ by 1 mrad
            assert error_f < 1e-3 and error_cop < 1e-3
        else:
            assert error_f < 1e-7 and error_cop < 1e-7


def test_uninitialised_plates_left_out_and_files_without_markers():
    plates, caught = _read("FP_Type1.c3d")
    assert [p.name for p in plates] == ["FP1"] and plates[0].never_loaded
    assert len(caught) == 3 and all("lies outside the lab" in m and "so it is left out" in m for m in caught)
    with pytest.raises(C3DError, match="contains no 3D points"):
        read_c3d(FOLDER / "Kistler.c3d")
    assert read_c3d(FOLDER / "Qualisys.c3d").positions.shape == (340, 55, 3)


@pytest.mark.parametrize("trial", [
    pytest.param(t, marks=pytest.mark.skipif(not (FOLDER / f"std_cop_{t}_grfs.sto").is_file(),
                                             reason=f"std_cop_{t}_grfs.sto is not in OPENFDK_C3D_SAMPLES"))
    for t in ("walking2", "walking5")])
def test_opensim_s_reference_ground_reactions(trial):
    """opensim-core's own walking trials (OpenSim/Tests/shared/walkingN.c3d) and
    the ground reactions OpenSim's C3DFileAdapter gives for them at the centre of pressure
    (OpenSim/Common/Test/std_cop_walkingN_grfs.sto: force N, point mm, free moment N·mm,
    every 0.05 s): both plates hold the force on the subject, and openfdk's reading
    equals OpenSim's."""
    from openfdk.io.storage import read_storage

    plates, caught = _read(f"{trial}.c3d")
    assert not caught and len(plates) == 2
    t, columns, _ = read_storage(FOLDER / f"std_cop_{trial}_grfs.sto")
    rows = np.round(t * plates[0].rate).astype(int)
    for i, plate in enumerate(plates, start=1):
        assert any("force on the subject" in n for n in plate.notes)
        force, point, torque = (np.column_stack([columns[f"{c}{i}_{j}"] for j in (1, 2, 3)]) for c in "fpm")
        on = plate.loaded[rows]
        assert on.sum() >= 10
        np.testing.assert_allclose(plate.force[rows], force, rtol=0, atol=1e-6)
        np.testing.assert_allclose(plate.cop[rows][on], point[on] * 1e-3, rtol=0, atol=1e-9)
        np.testing.assert_allclose(plate.free_moment[rows][on], torque[on] * 1e-3, rtol=0, atol=1e-8)
