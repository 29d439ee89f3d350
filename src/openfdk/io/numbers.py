"""Numbers as data files print them: decimal numbers, and the spellings C runtimes give
not-a-number and infinity.

Marker and storage files are mostly written by C and C++ programs (OpenSim, Mokka,
Vicon and Motion Analysis exporters). Their missing samples come out as whatever the
runtime's printf makes of NaN:

* glibc and most others: ``nan``, ``-nan``; C99's ``strtod`` (which OpenSim's readers
  use) also reads ``nan(n-char-sequence)``;
* Microsoft's C runtime since Visual Studio 2015: ``nan``, ``-nan(ind)`` (the
  "indefinite" NaN of an invalid operation such as 0/0), ``nan(snan)``, ``inf``;
* Microsoft's runtime before 2015: ``1.#QNAN``, ``-1.#IND``, ``1.#SNAN``, ``1.#INF``
  (often padded, ``1.#QNAN0``).

The DM treadmill trials of the sixth Knee Grand Challenge (``DM_ngait_tmf_slow1_new.trc``)
carry 4 996 ``-nan(ind)`` cells, for their sync-bar markers: OpenSim reads them as
missing, and so does openfdk. Everything else must be a plain decimal number: Python's
``float`` also reads ``1_000``, hexadecimal-looking or non-ASCII digits, which no data
file means.
"""

from __future__ import annotations

import math
import re

__all__ = ["NUMBER", "parse_number", "value_of_number"]

#: a decimal number, optionally signed and with an exponent (ASCII digits only)
DECIMAL = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z", re.ASCII)
#: C runtimes' not-a-number and infinity (module docstring); group 1 the sign, group 2 a
#: NaN spelling, group 3 an infinity spelling
SPECIAL = re.compile(r"([+-]?)(?:(nan(?:\([0-9a-z_]*\))?|1\.#(?:qnan|snan|ind)0*)|(inf|infinity|1\.#inf0*))\Z",
                     re.ASCII | re.IGNORECASE)
#: every value :func:`parse_number` reads (for a quick check of a whole row)
NUMBER = re.compile(rf"(?:{DECIMAL.pattern[:-2]}|{SPECIAL.pattern[:-2]})\Z", re.ASCII | re.IGNORECASE)


def parse_number(text: str) -> float:
    """The value of one cell ``text`` (str, surrounding whitespace ignored): a decimal
    number, NaN for any spelling of not-a-number, ±inf for infinity (module docstring).
    Raises ValueError for anything else, with the text in its message."""
    cell = text.strip()
    if DECIMAL.match(cell):
        return float(cell)
    m = SPECIAL.match(cell)
    if m is None:
        raise ValueError(f"{text!r} is not a number")
    if m.group(2):
        return math.nan
    return -math.inf if m.group(1) == "-" else math.inf


def value_of_number(cell: str) -> float:
    """:func:`parse_number` of a cell already matched by :data:`NUMBER`, by Python's float
    first (twice as fast on a storage file's 400 000 cells, where NaN spellings are rare)."""
    try:
        return float(cell)
    except ValueError:
        return parse_number(cell)
