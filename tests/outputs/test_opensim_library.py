"""The exported files in OpenSim itself (the ``opensim`` package from PyPI, an
independent reader; a test extra on Linux x86-64 / Python 3.11): the .sto tables load
with their labels and values, the .osim model builds, and the .mot coordinates applied
by OpenSim's FreeJoint put every body and marker where openfdk's kinematics has them."""

import numpy as np
import pandas as pd
import pytest

from openfdk.cli import main

osim = pytest.importorskip("opensim", reason="the opensim package (test extra) is not installed for this platform")


def _quat_matrix(e):
    e0, e1, e2, e3 = np.asarray(e, dtype=float) / np.linalg.norm(e)
    return np.array([
        [1 - 2 * (e2 * e2 + e3 * e3), 2 * (e1 * e2 - e0 * e3), 2 * (e1 * e3 + e0 * e2)],
        [2 * (e1 * e2 + e0 * e3), 1 - 2 * (e1 * e1 + e3 * e3), 2 * (e2 * e3 - e0 * e1)],
        [2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), 1 - 2 * (e1 * e1 + e2 * e2)]])


def test_opensim_reads_the_sto_tables(mandible_run):
    out, _ = mandible_run
    for name in ("kinematics", "forces"):
        csv = pd.read_csv(out / f"{name}.csv", index_col="time")
        numeric = [c for c in csv.columns if c not in ("message", "status", "fdk_reason")]
        table = osim.TimeSeriesTable(str(out / f"{name}.sto"))
        assert list(table.getColumnLabels()) == numeric
        np.testing.assert_array_equal(np.array(table.getIndependentColumn()), csv.index.to_numpy())
        np.testing.assert_array_equal(table.getMatrix().to_numpy(), csv[numeric].to_numpy(float))
        assert table.getTableMetaDataAsString("inDegrees") == "no"


def test_opensim_plays_the_exported_run(mandible_run, tmp_path):
    from openfdk.io.modelfile import load_model

    out, model_path = mandible_run
    bodies = [b.name for b in load_model(model_path).moving_bodies]
    assert {"skull", "mandible"} <= set(bodies)
    assert main(["export-opensim", str(out), "--out", str(tmp_path)]) == 0
    sink = osim.StringLogSink()
    old = osim.Logger.getLevelString()
    osim.Logger.setLevelString("info")
    osim.Logger.addSink(sink)
    try:
        model = osim.Model(str(next(tmp_path.glob("*.osim"))))
        model.initSystem()
    finally:
        osim.Logger.removeSink(sink)
        osim.Logger.setLevelString(old)
    usual = ("Updating Model file from", "Loaded model ")
    assert [x for x in sink.getString().splitlines() if x.strip() and not x.startswith(usual)] == []
    assert [model.getBodySet().get(i).getName() for i in range(model.getNumBodies())] == bodies
    assert model.getMarkerSet().getSize() == 8 and model.getNumCoordinates() == 6 * len(bodies)
    # the meshes load in Simbody (the library OpenSim draws them with)
    body = model.getBodySet().get("mandible")
    assert body.getPropertyByName("attached_geometry").size() == 3  # the two condyles and the bone
    for g in range(body.getPropertyByName("attached_geometry").size()):
        mesh = osim.PolygonalMesh()
        mesh.loadFile(str(tmp_path / osim.Mesh.safeDownCast(body.get_attached_geometry(g)).get_mesh_file()))
        assert mesh.getNumVertices() > 100 and mesh.getNumFaces() > 100
    motion = osim.TimeSeriesTable(str(next(tmp_path.glob("*.mot"))))
    kin = pd.read_csv(out / "kinematics.csv")
    coords = model.getCoordinateSet()
    labels = list(motion.getColumnLabels())
    checked = 0
    for i in (0, motion.getNumRows() // 2, motion.getNumRows() - 1):
        row = motion.getRowAtIndex(i)
        for j, label in enumerate(labels):
            coords.get(label).setDefaultValue(row[j])
        state = model.initializeState()  # FreeJoint: defaults -> body-fixed XYZ rotation + translation
        for name in bodies:
            T = model.getBodySet().get(name).getTransformInGround(state)
            R = np.array([[T.R().get(a, b) for b in range(3)] for a in range(3)])
            p = np.array([T.p().get(a) for a in range(3)])
            R_ref = _quat_matrix(kin.loc[i, [f"{name}.e{k}" for k in range(4)]])
            p_ref = kin.loc[i, [f"{name}.{c}_m" for c in "xyz"]].to_numpy(float)
            np.testing.assert_allclose(R, R_ref, atol=1e-12)
            np.testing.assert_allclose(p, p_ref, atol=1e-15, rtol=0)
            checked += 1
        # markers: OpenSim's location in ground vs the measured marker + residual of openfdk
        markers = model.getMarkerSet()
        for m in range(markers.getSize()):
            mk = markers.get(m)
            body_name = mk.getParentFrameName().rsplit("/", 1)[-1]
            loc = np.array([mk.get_location().get(a) for a in range(3)])
            R_ref = _quat_matrix(kin.loc[i, [f"{body_name}.e{k}" for k in range(4)]])
            p_ref = kin.loc[i, [f"{body_name}.{c}_m" for c in "xyz"]].to_numpy(float)
            g = mk.getLocationInGround(state)
            np.testing.assert_allclose([g.get(a) for a in range(3)], p_ref + R_ref @ loc, atol=1e-12)
    assert checked == 3 * len(bodies)
