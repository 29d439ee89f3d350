"""Cells of data files (openfdk.io.numbers): read as C's strtod reads them, which is what
OpenSim's readers use, and Microsoft's older NaN/Inf spellings as its documentation gives
them; anything else refused with the text in the message."""

import ctypes
import ctypes.util
import math

import numpy as np
import pytest

from openfdk.io.numbers import NUMBER, parse_number, value_of_number
from openfdk.io.storage import read_storage

LIBC = ctypes.CDLL(ctypes.util.find_library("c"))
LIBC.strtod.restype = ctypes.c_double
LIBC.strtod.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.c_char_p)]


def strtod(text):
    """(value, characters consumed) of C's strtod, the independent parser."""
    buf = ctypes.create_string_buffer(text.encode())
    end = ctypes.c_char_p()
    value = LIBC.strtod(buf, ctypes.byref(end))
    return value, ctypes.cast(end, ctypes.c_void_p).value - ctypes.addressof(buf)


# numbers and the NaN / Inf spellings strtod reads whole (glibc, and C99's nan(chars))
STRTOD_WHOLE = ["0", "-0", "1", "+2.5", "-2.5e3", ".5", "5.", "1e-300", "12345.678901", "nan", "NaN", "-nan",
                "nan(ind)", "-nan(ind)", "nan(snan)", "NAN(0x7ff8)", "nan()", "inf", "-inf", "Infinity",
                "-INFINITY"]


@pytest.mark.parametrize("text", STRTOD_WHOLE)
def test_a_cell_reads_as_c_strtod_reads_it(text):
    value, used = strtod(text)
    assert used == len(text)  # the oracle read the whole cell
    ours = parse_number(text)
    if math.isnan(value):
        assert math.isnan(ours)
    else:
        assert ours == value and math.copysign(1.0, ours) == math.copysign(1.0, value)
    assert NUMBER.match(text)
    fast = value_of_number(text)  # the storage reader's path for checked cells
    assert (math.isnan(fast) and math.isnan(ours)) or fast == ours


@pytest.mark.parametrize("text, expected", [
    # Microsoft's C runtime before Visual Studio 2015 (printf of NaN and Inf); strtod
    # stops at the '#', so these are checked against their documented meaning
    ("1.#QNAN", math.nan), ("-1.#QNAN", math.nan), ("1.#SNAN", math.nan), ("-1.#IND", math.nan),
    ("1.#IND00", math.nan), ("1.#QNAN0", math.nan), ("1.#INF", math.inf), ("-1.#INF", -math.inf),
    ("1.#INF00", math.inf),
])
def test_microsoft_legacy_spellings(text, expected):
    assert strtod(text)[1] < len(text)  # not C's syntax: strtod stops early
    for ours in (parse_number(text), value_of_number(text)):
        assert (math.isnan(ours) and math.isnan(expected)) or ours == expected


@pytest.mark.parametrize("text", ["", "abc", "1_000", "0x10", "nan(", "nan(a b)", "#N/A", "1.#", "1.#NAN",
                                  "\u0661", "1e", "--1", "inf inf", "nanx"])
def test_anything_else_is_refused_with_the_text(text):
    with pytest.raises(ValueError, match="is not a number"):
        parse_number(text)
    assert not NUMBER.match(text)


def test_a_storage_file_reads_windows_nan_as_missing_and_names_a_bad_column(tmp_path):
    """An OpenSim storage file written on Windows ('-nan(ind)') reads with NaN there; a
    cell that is no number is one line naming the line and the column."""
    head = "grf\nversion=1\nnRows=3\nnColumns=3\ninDegrees=no\nendheader\ntime\tfy\tpx\n"
    (tmp_path / "w.sto").write_text(head + "0\t1.5\t-nan(ind)\n0.01\t1.#QNAN\t2\n0.02\t-1.#IND\t3e-3\n")
    t, cols, in_degrees = read_storage(tmp_path / "w.sto")
    np.testing.assert_array_equal(t, [0.0, 0.01, 0.02])
    np.testing.assert_array_equal(np.isnan(cols["fy"]), [False, True, True])
    np.testing.assert_array_equal(np.isnan(cols["px"]), [True, False, False])
    assert cols["fy"][0] == 1.5 and cols["px"][2] == 3e-3 and not in_degrees
    (tmp_path / "b.sto").write_text(head + "0\t1.5\t2\n0.01\t1.#NAN\t2\n")
    with pytest.raises(ValueError, match=r"^b.sto: line 9: column 'fy' is '1.#NAN', expected a number$"):
        read_storage(tmp_path / "b.sto")
