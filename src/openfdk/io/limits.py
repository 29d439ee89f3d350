"""The documented size limits of openfdk's inputs, in one place (docs/input-checks.md,
"Size limits").

An input above a limit is refused before the expensive work starts — the file size is
taken from the file system before the file is read, a binary STL's triangle count from
its header, a YAML file's nodes and aliases from the parser's events before it is
composed and its expanded size from the node graph before any value is built, a
study's case count from its grid and lists before the cases are made — with one line
naming the file, the entry and the limit::

    model.yaml: line 3: 10 001 aliases (counted up to here), above the limit of 10 000 (openfdk.io.limits.YAML_ALIASES)

The readers look the values up here at call time, so a program that really needs more
may raise one (``openfdk.io.limits.MESH_TRIANGLES = 10_000_000``) before loading.

The values, and why:

* :data:`INPUT_FILE_BYTES` — model, subject, study and overlay YAML files and the
  OpenSim XML files (``.osim``, setup files, ExternalLoads): 64 MiB. The largest real
  files are a few MB (a full-body ``.osim`` with 92 muscles: about 1 MB, a mandible
  model file: a few kB); parsing holds about 10× the text in objects.
* :data:`YAML_ALIASES` — alias references (``*name``) in one YAML file: 10 000. Model
  files use a handful (shared settings); an alias bomb needs many.
* :data:`YAML_NODES` — YAML nodes of one file, counted from the parser's events before
  composing and once more with every alias expanded (what a reader that walks the
  values visits): 2 000 000. Composing, checking and building cost about 300 bytes and
  5 µs a node (2 million nodes of a 5.7 MiB file: 620 MB), so a file of short numbers
  within the byte limit would otherwise take gigabytes and minutes; a full-body model
  file has a few thousand nodes. An alias bomb of a dozen lines expands to 10¹² nodes.
* :data:`STUDY_CASES` — cases of one study (inputs × grid points and listed cases):
  100 000. Each case is a result folder and a row of the summary; a week of 6 s cases
  on 1 core.
* :data:`MESH_TRIANGLES` — triangles of one mesh file (contact or display): 5 000 000.
  Loading peaks at about 365 bytes per triangle (tracemalloc, a 320 000-triangle closed
  mesh: corners, merged vertices, edges, normals), so 1.8 GB — a tenth of the 24 GiB
  machine — and a binary STL of 250 MB. Bone surfaces have 10⁴–10⁶ triangles.
* :data:`MESH_FILE_BYTES` — mesh files other than binary STL (ASCII STL, OBJ, VTP, PLY):
  256 MiB, checked before reading. Parsing text holds several objects per number (an
  ASCII STL of 256 MiB is about a million triangles and 2.5 GB of tokens while read);
  a binary PLY of 256 MiB holds about 13 million triangles.
* :data:`VTP_ARRAY_VALUES` — values in one VTP DataArray: 30 000 000 (10 million points
  × 3 coordinates), checked against the declared counts before decoding.
* :data:`MAX_COORDINATE` — a coordinate in a model file: 10⁶ m; beyond it squared
  distances lose all precision. Not a size limit but a plausibility bound, kept here so
  every limit is in one place.

The distance-grid memory of contact meshes has its own, configurable limit
(``$OPENFDK_GRID_MEMORY_MB``, :mod:`openfdk.contact.limits`).
"""

from __future__ import annotations

import os

__all__ = ["INPUT_FILE_BYTES", "YAML_ALIASES", "YAML_NODES", "STUDY_CASES", "MESH_TRIANGLES", "MESH_FILE_BYTES",
           "VTP_ARRAY_VALUES", "MAX_COORDINATE", "over_limit", "check_count", "check_file_bytes"]

#: bytes of a model, subject, study or overlay YAML file, or an OpenSim XML file
INPUT_FILE_BYTES = 64 * 2**20
#: alias references (``*name``) in one YAML file
YAML_ALIASES = 10_000
#: nodes of one YAML file (as written, and with every alias expanded)
YAML_NODES = 2_000_000
#: cases of one study (inputs × parameter sets)
STUDY_CASES = 100_000
#: triangles of one mesh file
MESH_TRIANGLES = 5_000_000
#: bytes of a mesh file other than binary STL (ASCII STL, OBJ, VTP, PLY)
MESH_FILE_BYTES = 256 * 2**20
#: values of one VTP DataArray (10 million points × 3 coordinates)
VTP_ARRAY_VALUES = 30_000_000
#: largest plausible coordinate in a model file (m)
MAX_COORDINATE = 1e6


def _int(n) -> str:
    """``n`` with thin groups of three digits: 12 000."""
    return f"{int(n):,}".replace(",", " ")


def _limit_text(name) -> str:
    value = globals()[name]
    text = _int(value)
    if name.endswith("_BYTES") and value % 2**20 == 0:
        text += f" bytes ({value // 2**20} MiB)"
    return text


def over_limit(source, entry, amount, what, name) -> str:
    """The one-line message ``<source>: <entry>: <amount> <what>, above the limit of
    <value> (openfdk.io.limits.<name>)``; ``entry`` may be empty (the whole file), and
    ``source`` too (for readers whose callers put the file name in front)."""
    where = "".join(f"{part}: " for part in (source, entry) if part)
    return f"{where}{_int(amount)} {what}, above the limit of {_limit_text(name)} (openfdk.io.limits.{name})"


def check_count(amount, name, source, entry, what, error=ValueError):
    """Raise ``error`` (:func:`over_limit`'s message) when ``amount`` exceeds the limit
    ``name`` (a constant of this module, looked up now)."""
    if amount > globals()[name]:
        raise error(over_limit(source, entry, amount, what, name))


def check_file_bytes(path, name, source, error=ValueError):
    """Raise ``error`` when the file ``path`` is larger than the limit ``name`` (bytes),
    from its size on disk, before it is read. A file whose size cannot be read is left to
    the reader (which reports it)."""
    try:
        size = os.stat(path).st_size
    except (OSError, TypeError, ValueError):
        return
    check_count(size, name, source, "", "bytes", error)
