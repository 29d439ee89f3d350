"""openfdk.io.results.write_table: the CSV every analysis writes (kinematics.csv,
forces.csv, study summaries). Cells follow the documented format — floats with 10
significant digits, 'nan'/'inf', booleans as 0/1, integers as they are, text quoted by
the csv module when it holds a comma — whatever the column's container."""

import csv

import numpy as np
import pytest

from openfdk.io.results import write_table


def test_cells_follow_the_format_for_every_column_type(tmp_path):
    time = np.array([0.0, 0.01, 1.0 / 3.0])
    columns = {
        "time": time,
        "force_N": np.array([np.nan, -np.inf, 123456789.123456]),
        "tiny": np.array([1e-300, -0.0, 2.5], dtype=np.float32),
        "iterations": np.array([3, 0, 12], dtype=np.int64),
        "count": np.array([1, 2, 255], dtype=np.uint8),
        "converged": np.array([True, False, True]),
        "reason": ["", "line search failed, |f| = 0.5 N", "ok"],
        "label": np.array(["a", "b", "c"]),
        "mixed": [1.5, 2, True],
    }
    write_table(tmp_path / "t.csv", columns)
    text = (tmp_path / "t.csv").read_text()
    lines = text.splitlines()
    assert lines[0] == "time,force_N,tiny,iterations,count,converged,reason,label,mixed"
    assert lines[1] == "0,nan,0,3,1,1,,a,1.5"                 # float32 1e-300 underflows to 0
    assert lines[2] == '0.01,-inf,-0,0,2,0,"line search failed, |f| = 0.5 N",b,2'
    assert lines[3] == "0.3333333333,123456789.1,2.5,12,255,1,ok,c,1"
    rows = list(csv.reader((tmp_path / "t.csv").open()))
    assert rows[2][6] == "line search failed, |f| = 0.5 N"          # the comma stays in its cell
    assert float(rows[3][0]) == pytest.approx(1.0 / 3.0, rel=2e-10)   # 10 significant digits


def test_a_short_column_is_refused(tmp_path):
    with pytest.raises(ValueError, match="column 'b' has 2 rows, expected 3"):
        write_table(tmp_path / "t.csv", {"time": np.zeros(3), "b": np.zeros(2)})
    assert not (tmp_path / "t.csv").exists()


def test_read_table_gives_back_numbers_and_text(tmp_path):
    from openfdk.io.results import read_table

    t = np.linspace(0.0, 1.0, 7)
    columns = {"time": t, "F_N": np.sin(t) * 1e3, "ok": np.arange(7) % 2 == 0, "reason": ["a, b"] * 7}
    write_table(tmp_path / "t.csv", columns)
    back = read_table(tmp_path / "t.csv")
    assert list(back) == ["time", "F_N", "ok", "reason"]
    np.testing.assert_allclose(back["F_N"], columns["F_N"], rtol=1e-9)   # 10 significant digits
    np.testing.assert_array_equal(back["ok"], columns["ok"].astype(float))
    assert back["reason"] == ["a, b"] * 7


def test_table_columns_empty_cells_short_rows_and_no_rows():
    from openfdk.io.results import table_columns

    header = ["time", "x", "note"]
    body = [["0", "1.5", "ok"], ["0.1", "", "late"], ["0.2", "nan"]]          # a short last row
    strict = table_columns(header, body)
    assert strict["x"] == ["1.5", "", "nan"] and strict["note"] == ["ok", "late", ""]
    np.testing.assert_array_equal(strict["time"], [0.0, 0.1, 0.2])
    lenient = table_columns(header, body, empty_is_nan=True)
    np.testing.assert_array_equal(lenient["x"], [1.5, np.nan, np.nan])
    assert lenient["note"] == ["ok", "late", ""]                                # text stays text
    empty = table_columns(header, [])
    assert all(isinstance(c, np.ndarray) and c.size == 0 for c in empty.values())
