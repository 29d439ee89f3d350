"""OpenSim interoperability: TRC trials read like C3D, STO/MOT files round-trip through
an independent parser written here from the format description, and the exported
.osim + .mot reproduce the model and the run's body poses."""

import csv
import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from openfdk.cli import main
from openfdk.io.c3d import read_c3d, write_c3d
from openfdk.io.trc import TRCError, read_trc
from openfdk.io.trials import read_trial
from openfdk.fixtures.synthetic import synthetic_markers, two_body_model_dict


# ------------------------------------------------------------------ an independent TRC writer
def write_trc_opensim_layout(path, labels, positions_mm, rate, first_frame=1, units="mm", short_rows=()):
    """TRC as OpenSim documents it: 3 header lines, marker names over their x column
    followed by two empty cells, X1 Y1 Z1 labels, a blank line, then frame, time, x y z.
    Missing samples are empty cells; rows in ``short_rows`` stop after their last
    present marker (trailing markers missing)."""
    n_frames, n_markers, _ = positions_mm.shape
    lines = [f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{rate:g}\t{rate:g}\t{n_frames}\t{n_markers}\t{units}\t{rate:g}\t{first_frame}\t{n_frames}",
             "Frame#\tTime\t" + "\t".join(f"{lab}\t\t" for lab in labels),
             "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(n_markers)),
             ""]
    for k in range(n_frames):
        f = first_frame + k
        cells = [str(f), repr((f - first_frame) / rate)]
        for m in range(n_markers):
            p = positions_mm[k, m]
            cells += ["", "", ""] if np.any(np.isnan(p)) else [repr(float(v)) for v in p]
        if k in short_rows:
            while cells and cells[-1] == "":
                cells.pop()
        lines.append("\t".join(cells))
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture
def marker_data():
    t, labels, x, truth = synthetic_markers(60, rate=100.0, noise=0.0)
    x = x.copy()
    x[10:15, 2] = np.nan          # a gap in the middle
    x[40:, 7] = np.nan            # the last marker lost at the end: short rows
    x[0, 0] = np.nan              # the first sample of the first marker
    return t, labels, x


def test_trc_reads_to_the_same_trial_as_c3d_including_gaps(marker_data, tmp_path):
    t, labels, x = marker_data
    write_c3d(tmp_path / "trial.c3d", labels, x, 100.0, units="mm")
    write_trc_opensim_layout(tmp_path / "trial.trc", labels, x * 1e3, 100.0, short_rows=range(40, 60))
    # the short rows really are short (trailing markers absent)
    assert len((tmp_path / "trial.trc").read_text().splitlines()[6 + 45].split("\t")) == 2 + 3 * 7
    c3d, trc = read_c3d(tmp_path / "trial.c3d"), read_trc(tmp_path / "trial.trc")
    assert trc.labels == c3d.labels == tuple(labels)
    assert trc.rate == c3d.rate == 100.0
    np.testing.assert_allclose(trc.time, c3d.time, atol=1e-12)
    np.testing.assert_array_equal(np.isnan(trc.positions), np.isnan(c3d.positions))
    assert np.isnan(trc.positions).any(axis=2).sum() == 5 + 20 + 1
    # C3D stores float32 mm: 0.1 m is held to ~1e-8 m
    np.testing.assert_allclose(trc.positions, c3d.positions, atol=2e-8, rtol=0)
    np.testing.assert_allclose(trc.positions, x, atol=1e-15, rtol=1e-13)
    assert isinstance(read_trial(tmp_path / "trial.trc"), type(c3d))


def _opensim_markers(path):
    """labels, times (s) and positions (n, m, 3) in the file's units, as OpenSim 4.6 reads
    the TRC file."""
    osim = pytest.importorskip("opensim")
    table = osim.TimeSeriesTableVec3(str(path))
    rows, cols = table.getNumRows(), table.getNumColumns()
    p = np.array([[[table.getDependentColumnAtIndex(j)[i][k] for k in range(3)] for j in range(cols)]
                  for i in range(rows)])
    return list(table.getColumnLabels()), np.array(table.getIndependentColumn()), p


@pytest.mark.parametrize("between", ["\t", ""], ids=["one-empty-cell", "none"])
def test_trc_names_listed_in_order_are_read_as_opensim_reads_them(tmp_path, between):
    """OpenSim's Matlab utilities write line 4 as Frame#, Time, '', name, '', name …
    (its IK test data, std_walking2_markers.trc), an IMU export writes the names side by
    side: both are the names in order when there are NumMarkers of them."""
    t, labels, x, _ = synthetic_markers(60, rate=100.0, noise=0.0)   # no gaps: OpenSim
    write_trc_opensim_layout(tmp_path / "standard.trc", labels, x * 1e3, 100.0)   # drops empty cells
    text = (tmp_path / "standard.trc").read_text().splitlines()
    text[3] = "Frame#\tTime\t" + between + (between + "\t").join(labels)
    (tmp_path / "listed.trc").write_text("\n".join(text) + "\n")
    listed, standard = read_trc(tmp_path / "listed.trc"), read_trc(tmp_path / "standard.trc")
    assert listed.labels == standard.labels == tuple(labels)
    np.testing.assert_array_equal(listed.positions, standard.positions)
    names, times, p = _opensim_markers(tmp_path / "listed.trc")
    assert tuple(names) == listed.labels
    np.testing.assert_allclose(listed.time, times, atol=1e-12)
    np.testing.assert_allclose(listed.positions, p * 1e-3, atol=1e-15, rtol=1e-13)
    text[3] = "Frame#\tTime\t\t" + "\t\t".join(labels[1:])   # one name missing: refused
    (tmp_path / "short.trc").write_text("\n".join(text) + "\n")
    with pytest.raises(TRCError, match="short.trc: line 4"):
        read_trc(tmp_path / "short.trc")


def test_trc_with_fewer_rows_than_num_frames_reads_its_rows_with_a_warning(tmp_path):
    """OpenSim's walk_free_01.trc (its Matlab examples) declares 900 frames and holds 73:
    OpenSim reads the 73 rows silently; openfdk reads them and says so."""
    t, labels, x, _ = synthetic_markers(60, rate=100.0, noise=0.0)
    write_trc_opensim_layout(tmp_path / "cut.trc", labels, x * 1e3, 100.0)
    lines = (tmp_path / "cut.trc").read_text().splitlines()
    lines[2] = lines[2].replace("\t60\t", "\t900\t", 1)
    (tmp_path / "cut.trc").write_text("\n".join(lines[:6 + 25]) + "\n")
    with pytest.warns(UserWarning, match=r"cut.trc: NumFrames on line 3 is 900, the file has 25 data "
                                         r"rows; the 25 rows are read"):
        trc = read_trc(tmp_path / "cut.trc")
    assert trc.n_frames == 25
    np.testing.assert_allclose(trc.positions, x[:25], atol=1e-15, rtol=1e-13)
    names, times, p = _opensim_markers(tmp_path / "cut.trc")
    assert len(times) == 25 and tuple(names) == trc.labels


def test_trc_all_zero_samples_are_gaps_as_in_c3d(marker_data, tmp_path):
    """Exporters (the Knee Grand Challenge's TRCs among them) write a gap as ``-0 0 0``;
    the C3D reader already reads all-zero points as missing, and the TRC reader must agree."""
    t, labels, x = marker_data
    x = x.copy()
    x[20:30, 4] = 0.0
    x[5, 1] = (0.0, 0.0, 0.0)
    write_c3d(tmp_path / "trial.c3d", labels, x, 100.0, units="mm")
    write_trc_opensim_layout(tmp_path / "trial.trc", labels, x * 1e3, 100.0)
    text = (tmp_path / "trial.trc").read_text().replace("\t0.0\t0.0\t0.0", "\t-0\t0\t0")
    (tmp_path / "trial.trc").write_text(text)
    c3d, trc = read_c3d(tmp_path / "trial.c3d"), read_trc(tmp_path / "trial.trc")
    gaps = np.isnan(trc.positions).any(axis=2)
    assert gaps[20:30, 4].all() and gaps[5, 1]
    np.testing.assert_array_equal(gaps, np.isnan(c3d.positions).any(axis=2))
    # a marker with one coordinate exactly zero is still seen
    x[33, 3, 1] = 0.0
    write_trc_opensim_layout(tmp_path / "one.trc", labels, x * 1e3, 100.0)
    assert read_trc(tmp_path / "one.trc").positions[33, 3, 1] == 0.0


#: not-a-number and infinity as C runtimes print them (openfdk.io.numbers): glibc, C99
#: strtod's nan(chars), Microsoft's runtime since 2015 ('-nan(ind)', the Knee Grand
#: Challenge's treadmill TRCs) and before it
C_RUNTIME_GAPS = ("nan", "-nan", "-nan(ind)", "nan(snan)", "NaN(0x7ff8)", "1.#QNAN", "-1.#IND", "1.#QNAN0", "1.#INF",
                  "-inf")


def test_trc_gaps_in_every_c_runtime_spelling_of_nan_are_gaps(marker_data, tmp_path):
    """A sample written as not-a-number (or infinity) in any runtime's spelling is missing,
    as OpenSim's strtod-based reader takes it, and only that sample: the same gaps as the
    C3D of the same data."""
    t, labels, x = marker_data
    write_c3d(tmp_path / "trial.c3d", labels, x, 100.0, units="mm")
    write_trc_opensim_layout(tmp_path / "trial.trc", labels, x * 1e3, 100.0)
    lines = (tmp_path / "trial.trc").read_text().splitlines()
    for k, spelling in zip(range(10, 15), C_RUNTIME_GAPS[:5]):  # marker 2's gap, frames 10-14
        cells = lines[6 + k].split("\t")
        cells[2 + 3 * 2: 5 + 3 * 2] = [spelling] * 3
        lines[6 + k] = "\t".join(cells)
    gaps = {20: 5, 21: 5, 22: 6, 23: 6, 24: 6}  # new gaps, one coordinate each (x, y or z)
    for (k, m), spelling in zip(gaps.items(), C_RUNTIME_GAPS[5:]):
        cells = lines[6 + k].split("\t")
        cells[2 + 3 * m + k % 3] = spelling
        lines[6 + k] = "\t".join(cells)
    (tmp_path / "trial.trc").write_text("\n".join(lines) + "\n")
    trc, c3d = read_trc(tmp_path / "trial.trc"), read_c3d(tmp_path / "trial.c3d")
    expected = np.isnan(c3d.positions).any(axis=2)
    for k, m in gaps.items():
        expected[k, m] = True
    np.testing.assert_array_equal(np.isnan(trc.positions).any(axis=2), expected)
    assert expected.sum() == 26 + 5
    seen = ~expected
    np.testing.assert_allclose(trc.positions[seen], x[seen], rtol=1e-13)
    # the time column must still be a finite number
    cells = lines[6].split("\t")
    cells[1] = "-nan(ind)"
    (tmp_path / "bad.trc").write_text("\n".join([*lines[:6], "\t".join(cells), *lines[7:]]) + "\n")
    with pytest.raises(TRCError, match=r"bad.trc: line 7: the time is '-nan\(ind\)', expected a finite number"):
        read_trc(tmp_path / "bad.trc")


def test_trc_units_and_start_frame_come_from_the_header(marker_data, tmp_path):
    t, labels, x = marker_data
    write_trc_opensim_layout(tmp_path / "m.trc", labels, x, 50.0, first_frame=11, units="m")
    trial = read_trc(tmp_path / "m.trc")
    assert trial.rate == 50.0
    np.testing.assert_allclose(trial.time, np.arange(60) / 50.0)
    np.testing.assert_allclose(trial.positions, x, rtol=1e-15)


def _with_time_cells(path, cells):
    """The TRC at ``path`` with its Time column replaced by the text ``cells``."""
    lines = path.read_text().splitlines()
    for k, cell in enumerate(cells):
        row = lines[6 + k].split("\t")
        row[1] = cell
        lines[6 + k] = "\t".join(row)
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("rate, cells, on_grid", [
    # OpenSim's example files: 60 Hz times rounded to 1 ms
    (60.0, [f"{k / 60:.3f}" for k in range(60)], True),
    # the Knee Grand Challenge's treadmill TRCs: 120 Hz frame times rounded to 1 ms plus a
    # sync offset, some cells with a double's round-off digits
    (120.0, [repr(round(k / 120, 3) + 0.439997) for k in range(60)], True),
    # full precision
    (100.0, [repr(k / 100 + 2.2) for k in range(60)], True),
    # a dropped frame (two samples 2/rate apart): not a uniform grid, kept as read
    (100.0, [f"{(k + (k >= 30)) / 100:.3f}" for k in range(60)], False),
    # a time 0.3 ms off the grid printed to 0.1 ms: more than its precision, kept as read
    (100.0, [f"{k / 100 + 0.0003 * (k == 17):.4f}" for k in range(60)], False),
])
def test_trc_times_are_the_rate_s_grid_to_their_printed_precision(marker_data, tmp_path, rate, cells, on_grid):
    """Rounded Time columns (to 1 ms; the treadmill TRCs' 8 and 9 ms steps of a 120 Hz
    camera) are the uniform grid t_0 + k/rate the filter needs; times off the grid by more
    than their printed precision stay as read."""
    t, labels, x = marker_data
    write_trc_opensim_layout(tmp_path / "t.trc", labels, x * 1e3, rate)
    _with_time_cells(tmp_path / "t.trc", cells)
    read = np.array([float(c) for c in cells])
    if on_grid:
        assert np.ptp(np.diff(read)) > 0 or "e" in cells[1]  # the printed steps differ (or are exact)
        expected = read[0] + np.arange(60) / rate
    else:
        expected = read
    np.testing.assert_allclose(read_trc(tmp_path / "t.trc").time, expected, rtol=0, atol=1e-12)
    assert (np.ptp(np.diff(read_trc(tmp_path / "t.trc").time)) < 1e-9) == on_grid


def test_kinematics_from_trc_equals_kinematics_from_c3d(marker_data, tmp_path):
    t, labels, x = marker_data
    (tmp_path / "two_body.yaml").write_text(yaml.safe_dump(two_body_model_dict()))
    write_c3d(tmp_path / "trial.c3d", labels, x, 100.0, units="mm")
    write_trc_opensim_layout(tmp_path / "trial.trc", labels, x * 1e3, 100.0)
    for ext in ("c3d", "trc"):
        assert main(["kinematics", str(tmp_path / "two_body.yaml"), str(tmp_path / f"trial.{ext}"), "--out",
                     str(tmp_path / ext), "--no-progress", "--end", "0.3"]) == 0
    a, b = _csv_numeric(tmp_path / "c3d" / "kinematics.csv"), _csv_numeric(tmp_path / "trc" / "kinematics.csv")
    assert list(a) == list(b) and len(b["time"]) == 31
    assert np.ptp(b["jaw.x_m"]) > 5e-4  # the jaw moved (0.9 mm)
    poses = [c for c in b if c.endswith(("_m", ".e0", ".e1", ".e2", ".e3")) and not c.endswith("_m_s")]
    assert len(poses) == 2 * 7 + 8 * 3
    for c in poses:  # C3D's float32 storage: 1e-8 m per marker coordinate
        np.testing.assert_allclose(a[c], b[c], atol=1e-7, err_msg=c)
    assert json.loads((tmp_path / "trc" / "summary.json").read_text())["input"]["trial"].endswith("trial.trc")


@pytest.mark.parametrize("text, expected", [
    ("Something else\n" * 6, "line 1 must start with 'PathFileType'"),
    ("PathFileType\t4\t(X/Y/Z)\tx.trc\nDataRate\tNumMarkers\tUnits\n100\t1\tinch\nFrame#\tTime\tA\t\t\n\t\tX1\tY1\tZ1\n",
     "Units is 'inch'"),
    ("PathFileType\t4\t(X/Y/Z)\tx.trc\nDataRate\tNumMarkers\tUnits\n100\t2\tmm\nFrame#\tTime\tA\t\t\n\t\tX1\tY1\tZ1\n",
     "line 4 names 1 markers, NumMarkers on line 3 says 2"),
    ("PathFileType\t4\t(X/Y/Z)\tx.trc\nDataRate\tNumMarkers\tUnits\n100\t1\tmm\nFrame#\tTime\tA\t\t\n\t\tX1\tY1\tZ1\n"
     "\n1\t0\t1\t2\tabc\n", "line 7: column 5 is 'abc'"),
])
def test_bad_trc_is_reported_with_file_and_line(tmp_path, capsys, text, expected):
    bad = tmp_path / "bad.trc"
    bad.write_text(text)
    with pytest.raises(TRCError, match="bad.trc"):
        read_trc(bad)
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(two_body_model_dict()))
    assert main(["kinematics", str(tmp_path / "m.yaml"), str(bad), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.trc" in err and expected in err


def test_unknown_trial_extension_is_named(tmp_path, capsys):
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(two_body_model_dict()))
    (tmp_path / "trial.xyz").write_text("1 2 3\n")
    assert main(["kinematics", str(tmp_path / "m.yaml"), str(tmp_path / "trial.xyz"), "--out", str(tmp_path / "o"),
                 "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "trial.xyz" in err and ".c3d, .trc" in err


@pytest.mark.parametrize("command", ["run", "kinematics"])
def test_a_bad_trial_is_reported_before_the_model_is_loaded(tmp_path, capsys, monkeypatch, command):
    """The trial is read first: a user with a bad file hears of it at once, not after the
    model's set-up (DM: 80 s)."""
    import openfdk.analysis.jobs as jobs

    def not_yet(*args, **kwargs):
        raise AssertionError("the model was loaded before the trial was read")

    monkeypatch.setattr(jobs, "load_model_and_settings", not_yet)
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(two_body_model_dict()))
    bad = tmp_path / "bad.trc"
    bad.write_text("PathFileType\t4\t(X/Y/Z)\tx.trc\nDataRate\tNumMarkers\tUnits\n100\t1\tmm\n"
                   "Frame#\tTime\tA\t\t\n\t\tX1\tY1\tZ1\n\n1\t0\t1\t2\tabc\n")
    assert main([command, str(tmp_path / "m.yaml"), str(bad), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.trc: line 7: column 5 is 'abc'" in err


def test_a_trial_read_again_is_the_same_unless_its_bytes_changed(marker_data, tmp_path):
    """read_trial keeps the trials it read (the CLI reads the trial before the model and the
    analysis takes it again): the same file gives the same trial; a file rewritten with
    other bytes of the same length, at once (within the file system's clock tick), is read
    again."""
    t, labels, x = marker_data
    path = tmp_path / "trial.trc"
    write_trc_opensim_layout(path, labels, x * 1e3, 100.0)
    first = read_trial(path)
    assert read_trial(path) is first and not first.positions.flags.writeable
    text = path.read_text()
    cell = repr(float(x[30, 4, 0] * 1e3))
    changed = cell[:-1] + ("1" if cell[-1] != "1" else "2")
    assert text.count("\t" + cell + "\t") == 1
    path.write_text(text.replace("\t" + cell + "\t", "\t" + changed + "\t"))
    assert len(path.read_text()) == len(text)
    again = read_trial(path)
    assert again is not first
    assert again.positions[30, 4, 0] == pytest.approx(float(changed) * 1e-3, rel=1e-15)
    assert again.positions[30, 4, 0] != first.positions[30, 4, 0]


# ------------------------------------------------------------------ an independent STO/MOT parser
def parse_storage(path):
    """OpenSim storage file (documentation: name line, key=value lines, endheader, a
    tab-separated label line, numeric rows). Returns (name, fields, comments, labels,
    values (n_rows, n_columns))."""
    lines = path.read_text().split("\n")
    end = lines.index("endheader")
    name, fields, comments = lines[0], {}, []
    for line in lines[1:end]:
        key, eq, value = line.partition("=")
        if eq and " " not in key:
            fields[key] = value
        else:
            comments.append(line)
    labels = lines[end + 1].split("\t")
    rows = [[float(v) for v in line.split("\t")] for line in lines[end + 2:] if line != ""]
    return name, fields, comments, labels, np.array(rows)


def _csv_numeric(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    out = {}
    for j, label in enumerate(rows[0]):
        try:
            out[label] = np.array([float(r[j]) for r in rows[1:]])
        except ValueError:
            pass
    return out


def test_sto_files_round_trip_exactly(slider_run):
    out, _ = slider_run
    for table in ("kinematics", "forces"):
        csv_cols = _csv_numeric(out / f"{table}.csv")
        name, fields, comments, labels, values = parse_storage(out / f"{table}.sto")
        assert name == table
        assert fields == {"version": "1", "nRows": "101", "nColumns": str(len(csv_cols)), "inDegrees": "no"}
        assert labels == list(csv_cols)  # numeric columns, CSV order, time first
        assert values.shape == (101, len(labels))
        for j, label in enumerate(labels):
            np.testing.assert_array_equal(values[:, j], csv_cols[label], err_msg=label)
    _, _, comments, _, _ = parse_storage(out / "forces.sto")
    assert any("Text columns not stored: status, message" in c for c in comments)


def _opensim_table(path):
    """labels and (n, m) values of a storage file as OpenSim 4.6 reads it."""
    osim = pytest.importorskip("opensim")
    table = osim.TimeSeriesTable(str(path))
    values = np.array([[table.getDependentColumnAtIndex(j)[i] for j in range(table.getNumColumns())]
                       for i in range(table.getNumRows())])
    return list(table.getColumnLabels()), np.array(table.getIndependentColumn()), values


STO_HEADER = "states\nversion=1\nnRows=3\nnColumns=4\ninDegrees=no\nendheader\n"


@pytest.mark.parametrize("body, labels", [
    ("\t\t\n  \n\ntime\ta\tb\tc\n", ["a", "b", "c"]),      # blank lines after endheader (test.sto)
    ("time\ta\t\tb\tc\t\n", ["a", "b", "c"]),                # a double tab between labels (SinglePin)
], ids=["blank-lines", "double-tab"])
def test_sto_layouts_of_opensim_s_own_files_read_as_opensim_reads_them(tmp_path, body, labels):
    rows = np.array([[0.0, 1.5, -2.0, 3.25], [0.01, 1.0, 0.5, -1.0], [0.02, 0.0, 2.0, 4.0]])
    path = tmp_path / "s.sto"
    path.write_text(STO_HEADER + body + "".join("\t".join(repr(float(v)) for v in r) + "\n" for r in rows))
    from openfdk.io.storage import read_storage

    time, columns, _ = read_storage(path)
    names, t, values = _opensim_table(path)
    assert list(columns) == names == labels
    np.testing.assert_array_equal(time, t)
    np.testing.assert_array_equal(np.column_stack(list(columns.values())), values)


def test_sto_columns_given_twice(tmp_path):
    """OpenSim's gait-tutorial IK files (subject01_walk1_ik.mot) label both plates'
    ground reactions alike: the columns given twice with different values are left out
    with a warning, and the others read as OpenSim reads them; identical ones are one
    column; a second 'time' is refused."""
    from openfdk.io.storage import read_storage

    rows = np.array([[0.0, 0.1, 10.0, 20.0, 7.0, 7.0], [0.01, 0.2, 11.0, 21.0, 8.0, 8.0]])
    path = tmp_path / "ik.mot"
    path.write_text(STO_HEADER + "time\tknee\tground_force_vy\tground_force_vy\tx\tx\n"
                    + "".join("\t".join(repr(float(v)) for v in r) + "\n" for r in rows))
    with pytest.warns(UserWarning, match=r"ik.mot: line 7: columns \['ground_force_vy'\] are given twice "
                                         r"with different values; they are not read"):
        time, columns, _ = read_storage(path)
    assert list(columns) == ["knee", "x"]
    names, _, values = _opensim_table(path)
    for label in columns:
        np.testing.assert_array_equal(columns[label], values[:, names.index(label)])
    path.write_text(STO_HEADER + "time\ta\ttime\n0\t1\t0\n0.1\t2\t0.1\n")
    with pytest.raises(ValueError, match="column 'time' is given twice"):
        read_storage(path)


def test_write_storage_nan_and_header(tmp_path):
    from openfdk.io.storage import write_storage

    t = np.array([0.0, 0.1, 0.2])
    write_storage(tmp_path / "a.mot", t, {"q1": [1.0, np.nan, 1 / 3], "q2": [1e-300, -2.5, 7.0]}, name="coords",
                  in_degrees=True, comments=["hello"])
    name, fields, comments, labels, values = parse_storage(tmp_path / "a.mot")
    assert (name, fields["inDegrees"], fields["nRows"], fields["nColumns"], comments) == ("coords", "yes", "3", "3",
                                                                                          ["hello"])
    assert labels == ["time", "q1", "q2"]
    np.testing.assert_array_equal(values, [[0.0, 1.0, 1e-300], [0.1, np.nan, -2.5], [0.2, 1 / 3, 7.0]])
    with pytest.raises(ValueError, match="tab"):
        write_storage(tmp_path / "b.sto", t, {"a\tb": t})


# ------------------------------------------------------------------ the .osim export
def _Rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _Ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _Rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _quat_matrix(e):
    """Rotation matrix of a unit quaternion (scalar first), Euler–Rodrigues."""
    e0, e1, e2, e3 = np.asarray(e) / np.linalg.norm(e)
    return np.array([
        [1 - 2 * (e2 * e2 + e3 * e3), 2 * (e1 * e2 - e0 * e3), 2 * (e1 * e3 + e0 * e2)],
        [2 * (e1 * e2 + e0 * e3), 1 - 2 * (e1 * e1 + e3 * e3), 2 * (e2 * e3 - e0 * e1)],
        [2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), 1 - 2 * (e1 * e1 + e2 * e2)]])


def _floats(el, tag):
    return np.array([float(v) for v in el.find(tag).text.split()])


def _offset(joint, which):
    """(parent frame path, p (3,), R (3, 3)) of a joint's parent or child offset frame
    (OpenSim's PhysicalOffsetFrame: orientation = body-fixed X-Y-Z angles)."""
    name = joint.find(f"socket_{which}_frame").text
    (f,) = [f for f in joint.find("frames") if f.get("name") == name]
    a, b, c = _floats(f, "orientation")
    return f.find("socket_parent").text, _floats(f, "translation"), _Rx(a) @ _Ry(b) @ _Rz(c)


def _joint_transform(joint, q):
    """(p_FM (3,), R_FM (3, 3)) of an exported joint at coordinates q {name: value},
    written from OpenSim's joint definitions (FreeJoint: Rx Ry Rz and a translation in F;
    PinJoint: Rz; CustomJoint: linear or constant axes, rotations intrinsic)."""
    names = [c.get("name") for c in joint.find("coordinates")] if joint.find("coordinates") is not None else []
    if joint.tag == "FreeJoint":
        rx, ry, rz, tx, ty, tz = (q[n] for n in names)
        return np.array([tx, ty, tz]), _Rx(rx) @ _Ry(ry) @ _Rz(rz)
    if joint.tag == "PinJoint":
        return np.zeros(3), _Rz(q[names[0]])
    assert joint.tag == "CustomJoint", joint.tag
    R, p = np.eye(3), np.zeros(3)
    for k, ta in enumerate(joint.find("SpatialTransform")):
        axis = _floats(ta, "axis")
        fn = ta[-1]
        if fn.tag == "Constant":
            value = float(fn.find("value").text)
        else:
            assert fn.tag == "LinearFunction"
            slope, intercept = _floats(fn, "coefficients")
            value = slope * q[ta.find("coordinates").text] + intercept
        if k < 3:
            K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            R = R @ (np.eye(3) + np.sin(value) * K + (1 - np.cos(value)) * K @ K)
        else:
            p = p + value * axis
    return p, R


def check_export(result_dir, model, out, joint_tags=None):
    """The .osim and .mot of a run against the model and kinematics.csv: every body's
    pose rebuilt from the .mot's coordinates through the exported joints (parent before
    child) equals the run's."""
    assert main(["export-opensim", str(result_dir), "--out", str(out)]) == 0
    osim = next(out.glob("*.osim"))
    root = ET.parse(osim).getroot()  # well-formed XML
    assert root.tag == "OpenSimDocument" and root.get("Version") == "40000"
    m = root.find("Model")
    moving = [b for b in model.bodies[1:]]
    bodies = {b.get("name"): b for b in m.find("BodySet/objects")}
    assert list(bodies) == [b.name for b in moving]
    joints = list(m.find("JointSet/objects"))
    assert [j.tag for j in joints] == (joint_tags or ["FreeJoint"] * len(moving))
    for b in moving:
        el = bodies[b.name]
        assert float(el.find("mass").text) == b.mass
        np.testing.assert_array_equal(_floats(el, "mass_center"), 0.0)
        J = b.inertia_B
        np.testing.assert_array_equal(_floats(el, "inertia"), [J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]])
    for j in joints:
        if j.tag == "FreeJoint":
            body = j.get("name").removesuffix("_free")
            assert _offset(j, "parent")[0] == "/ground" and _offset(j, "child")[0] == f"/bodyset/{body}"
            for which in ("parent", "child"):
                np.testing.assert_array_equal(_offset(j, which)[1], 0.0)
                np.testing.assert_array_equal(_offset(j, which)[2], np.eye(3))
            assert [c.get("name") for c in j.find("coordinates")] == [f"{body}_{s}" for s in
                                                                       ("rx", "ry", "rz", "tx", "ty", "tz")]
    markers = list(m.find("MarkerSet/objects"))
    assert [mk.get("name") for mk in markers] == list(model.markers.labels)
    for j, mk in enumerate(markers):
        body = model.bodies[model.markers.body[j]].name
        assert mk.find("socket_parent_frame").text == f"/bodyset/{body}"
        np.testing.assert_array_equal(_floats(mk, "location"), model.markers.p_BM[j])
    # geometry: every contact surface as a mesh on its body, vertices in the body frame
    meshes = {g.get("name"): (g.find("mesh_file").text, body.get("name"))
              for body in m.iter() if body.tag in ("Body", "Ground") for g in body.iter("Mesh")}
    contacts = model.contacts
    assert len(meshes) == 2 * len(contacts) + len(model.visuals)
    for c in contacts:
        for side, bi, surf in (("vertices", c.body_a, c.pair.surface_A), ("surface", c.body_b, c.pair.surface_B)):
            fname, owner = meshes[f"{c.name}_{side}"]
            assert owner == (model.bodies[bi].name if bi else "ground")
            lines = (out / fname).read_text().splitlines()
            v = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
            f = np.array([[int(x) - 1 for x in ln.split()[1:]] for ln in lines if ln.startswith("f ")])
            np.testing.assert_array_equal(v, surf.vertices_B)
            np.testing.assert_array_equal(f, surf.faces)
    # the motion: the joints applied to the coordinates give the run's poses
    name, fields, comments, labels, values = parse_storage(next(out.glob("*.mot")))
    assert fields["inDegrees"] == "no"
    kin = _csv_numeric(result_dir / "kinematics.csv")
    np.testing.assert_array_equal(values[:, 0], kin["time"])
    col = {lab: values[:, i] for i, lab in enumerate(labels)}
    n_checked = 0
    for i in range(len(values)):
        pose = {"/ground": (np.zeros(3), np.eye(3))}
        for j in joints:
            q = {c.get("name"): col[c.get("name")][i] for c in (j.find("coordinates") or [])}
            parent, p_PF, R_PF = _offset(j, "parent")
            child, p_CM, R_CM = _offset(j, "child")
            p_WP, R_WP = pose[parent]
            p_FM, R_FM = _joint_transform(j, q)
            R_WM = R_WP @ R_PF @ R_FM
            p_WM = p_WP + R_WP @ p_PF + R_WP @ R_PF @ p_FM
            R_WC = R_WM @ R_CM.T
            pose[child] = (p_WM - R_WC @ p_CM, R_WC)
        for b in moving:
            p, R = pose[f"/bodyset/{b.name}"]
            np.testing.assert_allclose(R, _quat_matrix([kin[f"{b.name}.e{k}"][i] for k in range(4)]), atol=1e-12)
            np.testing.assert_allclose(p, [kin[f"{b.name}.{c}_m"][i] for c in "xyz"], atol=1e-9, rtol=0)
            n_checked += 1
    assert n_checked == len(moving) * len(values)
    return col


def test_export_opensim_slider_crank_reproduces_the_poses(slider_run, tmp_path):
    from openfdk.io.modelfile import load_model

    out, model_path = slider_run
    col = check_export(out, load_model(model_path), tmp_path / "osim", ["PinJoint", "PinJoint", "CustomJoint"])
    # the crank turns once: its pin angle is unwrapped (continuous) through 2π
    rz = col["crank_pin_rz"]
    assert np.max(np.abs(np.diff(rz))) < 0.1 and np.ptp(rz) > 6.0


def test_export_opensim_mandible_model_with_meshes_and_markers(mandible_run, tmp_path):
    from openfdk.io.modelfile import load_model

    out, model_path = mandible_run
    model = load_model(model_path)
    assert len(model.contacts) == 2 and model.markers.size == 8
    check_export(out, model, tmp_path / "osim")


def test_export_without_a_model_file_is_one_line(slider_run, tmp_path, capsys):
    import shutil

    out, _ = slider_run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    summary = json.loads((copy / "summary.json").read_text())
    summary["input"] = {"model": "nowhere.yaml"}
    (copy / "summary.json").write_text(json.dumps(summary))
    assert main(["export-opensim", str(copy), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "summary.json" in err and "--model" in err


def test_export_includes_visual_meshes_in_the_body_frame(slider_run, tmp_path):
    """A `visual:` mesh (STL in mm, placed 10 mm along x and turned 90° about z on the
    crank) is exported as OBJ vertices v_B = Rz(90°)·(v_file/1000) + (0.01, 0, 0) m with
    its colour."""
    import trimesh

    out, model_path = slider_run
    data = yaml.safe_load(model_path.read_text())
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=8.0)
    sphere.apply_translation([3.0, -2.0, 1.0])
    sphere.export(tmp_path / "crank.stl")
    data["bodies"]["crank"]["visual"] = {"mesh": "crank.stl", "units": "mm", "color": "#ff8000",
                                         "placement": {"position": [10, 0, 0], "orientation": [0, 0, 90]}}
    (tmp_path / "slider.yaml").write_text(yaml.safe_dump(data))
    assert main(["export-opensim", str(out), "--out", str(tmp_path / "osim"), "--model",
                 str(tmp_path / "slider.yaml")]) == 0
    root = ET.parse(next((tmp_path / "osim").glob("*.osim"))).getroot()
    crank = [b for b in root.iter("Body") if b.get("name") == "crank"][0]
    mesh = crank.find("attached_geometry/Mesh")
    assert mesh.find("mesh_file").text == "Geometry/crank_visual_0.obj"
    np.testing.assert_allclose([float(c) for c in mesh.find("Appearance/color").text.split()], [1.0, 128 / 255, 0.0],
                               atol=1e-6)
    lines = (tmp_path / "osim" / "Geometry" / "crank_visual_0.obj").read_text().splitlines()
    v = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    stl = trimesh.load(tmp_path / "crank.stl", force="mesh", process=False)
    assert len(v) == len(stl.vertices) or len(v) == len(np.unique(stl.vertices.round(6), axis=0))
    expected = stl.vertices / 1000.0 @ _Rz(np.pi / 2).T + [0.01, 0.0, 0.0]
    # same point set (loaders may merge or reorder duplicated STL vertices)
    d = np.linalg.norm(v[:, None, :] - expected[None, :, :], axis=2)
    assert d.min(axis=1).max() < 1e-9 and d.min(axis=0).max() < 1e-9
