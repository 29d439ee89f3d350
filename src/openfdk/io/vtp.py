"""VTK XML PolyData (``.vtp``) triangle meshes: the bone geometry of OpenSim models.

The format (VTK's "VTK File Formats", XML section) as OpenSim's ``Geometry`` folders
hold it::

    <VTKFile type="PolyData" version="0.1" byte_order="LittleEndian"
             header_type="UInt32" compressor="vtkZLibDataCompressor">
      <PolyData>
        <Piece NumberOfPoints="4" NumberOfVerts="0" NumberOfLines="0"
               NumberOfStrips="0" NumberOfPolys="4">
          <PointData Normals="Normals"> <DataArray Name="Normals" .../> </PointData>
          <Points> <DataArray type="Float32" NumberOfComponents="3" format="ascii">
            x0 y0 z0 x1 y1 z1 … </DataArray> </Points>
          <Polys>
            <DataArray type="Int32" Name="connectivity" format="ascii"> 0 1 2 … </DataArray>
            <DataArray type="Int32" Name="offsets" format="ascii"> 3 6 … </DataArray>
          </Polys>
        </Piece>
      </PolyData>
    </VTKFile>

``offsets`` holds the end of each polygon in ``connectivity``. A ``DataArray`` is
``format="ascii"`` (whitespace-separated numbers) or ``format="binary"``: base64 of a
header of ``header_type`` integers (UInt32 by default, in ``byte_order``) and the raw
values. Without a ``compressor`` the header is one integer, the number of data bytes;
with ``compressor="vtkZLibDataCompressor"`` it is ``[n_blocks, block_size,
last_block_size, compressed_size_0, …]`` and the data are n_blocks zlib streams that
inflate to block_size bytes each (the last to last_block_size, or block_size when 0).
VTK encodes the header and the data as two separate base64 texts, one after the other;
both forms are read. ``format="appended"`` (data in an ``<AppendedData>`` section) is not
supported.

Polygons with more than 3 corners are fan-triangulated, triangle strips (``<Strips>``)
split; vertices (``<Verts>``), lines (``<Lines>``), normals and other point data are
ignored. Several ``<Piece>`` elements are joined into one mesh.

Hostile files: the XML is parsed by lxml without entity expansion, network access or
huge-tree mode, and a DOCTYPE is refused; every count is checked against the declared
``NumberOf…`` attributes and capped at :data:`MAX_VALUES` values per array (and at
:data:`openfdk.io.limits.MESH_TRIANGLES` triangles per cell kind, from the offsets,
before the connectivity is decoded; the file at :data:`openfdk.io.limits.MESH_FILE_BYTES`
before it is read); zlib blocks
are inflated at most to their declared size, which must equal what the declared counts
need. Without huge-tree mode one text node holds at most 10 MB (an ascii array of about
200 000 points as VTK writes them, a binary one of about 600 000); larger arrays are
refused. Every problem raises one ``ValueError`` line ``<file>: <what is wrong>``.
"""

from __future__ import annotations

import base64
import binascii
import zlib

import numpy as np

from . import limits
from .polygons import fan_triangles, parse_mesh_file, strip_triangles

__all__ = ["MAX_VALUES", "read_vtp"]

#: most values one DataArray may hold: :data:`openfdk.io.limits.VTP_ARRAY_VALUES`
MAX_VALUES = limits.VTP_ARRAY_VALUES

_TYPES = {"Float32": "f4", "Float64": "f8", "Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2",
          "Int32": "i4", "UInt32": "u4", "Int64": "i8", "UInt64": "u8"}
_FLOATS = ("Float32", "Float64")
_INTS = tuple(t for t in _TYPES if t not in _FLOATS)
_ZLIB = "vtkZLibDataCompressor"


def read_vtp(path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(n, 3)`` float64 (the file's length unit) and triangles ``(m, 3)``
    int64 (vertex indices, the file's winding) of the VTK XML PolyData file ``path``.
    Raises ``ValueError("<path>: <what is wrong>")`` (one line) when the file cannot be
    read or is not a valid PolyData file of the supported kind."""
    return parse_mesh_file(path, _parse, (zlib.error, binascii.Error))


def _parse(data: bytes):
    from lxml import etree

    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        msg = getattr(exc, "msg", None) or str(exc)
        if "Text node too long" in msg:
            raise ValueError(f"a data array holds more than 10 MB of text, beyond what is read without "
                             f"huge-tree mode ({msg}); save the mesh with binary (zlib) data arrays") from None
        raise ValueError(f"not a well-formed XML file ({msg})") from None
    if root is None:
        raise ValueError("not an XML file")
    if root.getroottree().docinfo.doctype:
        raise ValueError("has a DOCTYPE declaration (VTK files have none; refused)")
    if root.tag != "VTKFile":
        raise ValueError(f"the root element is <{root.tag}>, not <VTKFile>")
    if root.get("type") != "PolyData":
        raise ValueError(f"VTKFile type is {root.get('type')!r}, not 'PolyData'")
    enc = _Encoding(root)
    poly = root.find("PolyData")
    if poly is None:
        raise ValueError("no <PolyData> element in <VTKFile>")
    pieces = poly.findall("Piece")
    if not pieces:
        raise ValueError("no <Piece> element in <PolyData>")
    vertices, triangles, n = [], [], 0
    for k, piece in enumerate(pieces):
        v, t = _piece(piece, enc, f"Piece {k}: " if len(pieces) > 1 else "")
        vertices.append(v)
        triangles.append(t + n)
        n += len(v)
    return np.concatenate(vertices), np.concatenate(triangles)


class _Encoding:
    """byte order, header type and compressor of a VTKFile."""

    def __init__(self, root):
        order = root.get("byte_order", "LittleEndian")
        if order not in ("LittleEndian", "BigEndian"):
            raise ValueError(f"unknown byte_order {order!r}; expected 'LittleEndian' or 'BigEndian'")
        self.order = "<" if order == "LittleEndian" else ">"
        header = root.get("header_type", "UInt32")
        if header not in ("UInt32", "UInt64"):
            raise ValueError(f"unknown header_type {header!r}; expected 'UInt32' or 'UInt64'")
        self.header = np.dtype(self.order + _TYPES[header])
        self.compressor = root.get("compressor") or ""
        if self.compressor not in ("", _ZLIB):
            raise ValueError(f"compressor {self.compressor!r} is not supported (only {_ZLIB!r})")


def _count(el, attr, label, default=None) -> int:
    text = el.get(attr)
    if text is None:
        if default is None:
            raise ValueError(f"{label}<{el.tag}> has no {attr} attribute")
        return default
    try:
        n = int(text.strip())
    except ValueError:
        raise ValueError(f"{label}<{el.tag}> {attr}={text!r} is not a count") from None
    if not 0 <= n <= limits.VTP_ARRAY_VALUES:
        raise ValueError(f"{label}<{el.tag}> {attr}={n} is out of range [0, {limits.VTP_ARRAY_VALUES}]")
    return n


def _piece(piece, enc, label):
    """(vertices (n, 3) float64, triangles (m, 3) int64) of one <Piece>."""
    n_points = _count(piece, "NumberOfPoints", label)
    points = piece.find("Points")
    if points is None or points.find("DataArray") is None:
        if n_points:
            raise ValueError(f"{label}<Piece> has NumberOfPoints={n_points} but no <Points><DataArray>")
        vertices = np.zeros((0, 3))
    else:
        da = points.find("DataArray")
        vertices = _array(da, enc, 3 * n_points, _FLOATS, f"{label}Points", 3).reshape(-1, 3)
        bad = ~np.isfinite(vertices).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"{label}point {i} has a non-finite coordinate {vertices[i].tolist()}")
    triangles = [np.zeros((0, 3), np.int64)]
    for tag, attr, split in (("Polys", "NumberOfPolys", fan_triangles), ("Strips", "NumberOfStrips", strip_triangles)):
        n_cells = _count(piece, attr, label, default=0)
        if not n_cells:
            continue
        cells = piece.find(tag)
        if cells is None:
            raise ValueError(f"{label}<Piece> has {attr}={n_cells} but no <{tag}>")
        arrays = {da.get("Name"): da for da in cells.findall("DataArray")}
        for name in ("connectivity", "offsets"):
            if name not in arrays:
                raise ValueError(f"{label}<{tag}> has no DataArray Name={name!r}")
        ends = _array(arrays["offsets"], enc, n_cells, _INTS, f"{label}{tag} offsets", 1)
        if np.any(np.diff(ends) <= 0) or ends[0] <= 0:
            i = int(np.argmax(np.diff(np.concatenate([[0], ends])) <= 0))
            raise ValueError(f"{label}{tag} offsets are not increasing (offset {i} is {ends[i]})")
        if ends[-1] > limits.VTP_ARRAY_VALUES:
            raise ValueError(f"{label}{tag} offsets end at {ends[-1]}, beyond {limits.VTP_ARRAY_VALUES} indices")
        n_triangles = int(ends[-1]) - 2 * n_cells   # k - 2 per cell of k corners
        limits.check_count(n_triangles, "MESH_TRIANGLES", "", f"{label}<{tag}>", "triangles")
        conn = _array(arrays["connectivity"], enc, int(ends[-1]), _INTS, f"{label}{tag} connectivity", 1)
        if len(conn) and (conn.min() < 0 or conn.max() >= n_points):
            i = int(np.argmax((conn < 0) | (conn >= n_points)))
            raise ValueError(f"{label}{tag} connectivity index {conn[i]} (entry {i}) is out of range "
                             f"for {n_points} points")
        triangles.append(split(conn, ends, f"{label}{tag}"))
    return vertices, np.concatenate(triangles)


def _array(da, enc, count, types, what, components) -> np.ndarray:
    """The ``count`` values (float64 or int64, flat) of a <DataArray>, checked."""
    if count > limits.VTP_ARRAY_VALUES:
        raise ValueError(f"{what} DataArray would hold {count} values, beyond {limits.VTP_ARRAY_VALUES}")
    kind = da.get("type")
    if kind not in types:
        raise ValueError(f"{what} DataArray type {kind!r} is not one of {list(types)}")
    nc = da.get("NumberOfComponents", "1").strip()
    if nc != str(components):
        raise ValueError(f"{what} DataArray has NumberOfComponents={nc!r}, expected {components}")
    fmt = da.get("format")
    # the values are the element's own text and the tails of its children (VTK may write
    # <InformationKey> children before the values); the children's text is not data
    text = (da.text or "") + "".join(child.tail or "" for child in da)
    if fmt == "ascii":
        tokens = text.split()
        if len(tokens) != count:
            raise ValueError(f"{what} DataArray holds {len(tokens)} values, expected {count}")
        target = np.float64 if kind in _FLOATS else np.int64
        try:
            values = np.array(tokens, dtype=target) if tokens else np.zeros(0, target)
        except (ValueError, OverflowError):
            expected = "a number" if target is np.float64 else "an integer"
            raise ValueError(f"{what} DataArray holds a value that is not {expected}") from None
        return values
    if fmt == "binary":
        dtype = np.dtype(enc.order + _TYPES[kind])
        raw = _b64decode("".join(text.split()), what)
        unpack = _inflate if enc.compressor else _plain
        payload = unpack(raw, enc, count * dtype.itemsize, what)
        values = np.frombuffer(payload, dtype=dtype)
        if kind in _FLOATS:
            return values.astype(np.float64)
        if kind == "UInt64" and len(values) and values.max() > np.iinfo(np.int64).max:
            raise ValueError(f"{what} DataArray holds an index beyond the Int64 range")
        return values.astype(np.int64)
    if fmt == "appended":
        raise ValueError(f"{what} DataArray format 'appended' (an <AppendedData> section) is not supported; "
                         "save the file with ascii or binary (inline) data arrays")
    raise ValueError(f"{what} DataArray format {fmt!r} is unknown; expected 'ascii' or 'binary'")


def _b64decode(text: str, what) -> bytes:
    """Bytes of base64 ``text`` that may be several padded base64 texts one after the
    other (VTK encodes a binary array's header and data separately)."""
    if len(text) % 4:
        raise ValueError(f"{what} DataArray base64 text has {len(text)} characters, not a multiple of 4 (truncated?)")
    out, start = [], 0
    try:
        while start < len(text):
            i = text.find("=", start)
            end = len(text) if i < 0 else (i // 4 + 1) * 4
            out.append(base64.b64decode(text[start:end], validate=True))
            start = end
    except (binascii.Error, ValueError):
        raise ValueError(f"{what} DataArray holds text that is not base64") from None
    return b"".join(out)


def _header(raw, enc, n, what):
    size = n * enc.header.itemsize
    if len(raw) < size:
        raise ValueError(f"{what} DataArray binary data ({len(raw)} bytes) is shorter than its header ({size} bytes)")
    return [int(x) for x in np.frombuffer(raw, dtype=enc.header, count=n)]


def _plain(raw, enc, nbytes, what) -> bytes:
    """The data bytes of an uncompressed binary array: [byte count][data]."""
    (declared,) = _header(raw, enc, 1, what)
    h = enc.header.itemsize
    if declared != nbytes:
        raise ValueError(f"{what} DataArray header declares {declared} bytes, the declared counts need {nbytes}")
    if len(raw) - h != nbytes:
        raise ValueError(f"{what} DataArray binary data holds {len(raw) - h} bytes, expected {nbytes} (truncated?)")
    return raw[h:]


def _inflate(raw, enc, nbytes, what) -> bytes:
    """The data bytes of a zlib-compressed binary array, inflated block by block to at
    most the sizes its header declares, which must add up to ``nbytes``."""
    h = enc.header.itemsize
    n_blocks, block, last = _header(raw, enc, 3, what)
    if n_blocks > (len(raw) - 3 * h) // h:
        raise ValueError(f"{what} DataArray compression header declares {n_blocks} blocks, more than the data can hold")
    sizes = _header(raw, enc, 3 + n_blocks, what)[3:]
    if n_blocks and (block <= 0 or last > block):
        raise ValueError(f"{what} DataArray compression header has block size {block} and last block size {last}")
    expect = [block] * n_blocks
    if n_blocks and last:
        expect[-1] = last
    if sum(expect) != nbytes:
        raise ValueError(f"{what} DataArray compression header declares {sum(expect)} bytes, "
                         f"the declared counts need {nbytes}")
    payload = memoryview(raw)[(3 + n_blocks) * h:]
    if sum(sizes) != len(payload):
        raise ValueError(f"{what} DataArray compressed data holds {len(payload)} bytes, "
                         f"its header declares {sum(sizes)} (truncated?)")
    out, at = [], 0
    for k, (csize, usize) in enumerate(zip(sizes, expect)):
        d = zlib.decompressobj()
        try:
            chunk = d.decompress(payload[at:at + csize], usize)   # never more than usize bytes
            if len(chunk) == usize and not d.eof and d.decompress(d.unconsumed_tail, 1):
                raise ValueError(f"{what} DataArray zlib block {k} inflates to more than its declared {usize} bytes")
        except zlib.error as exc:
            raise ValueError(f"{what} DataArray zlib block {k} is corrupt ({exc})") from None
        if len(chunk) != usize or not d.eof or d.unused_data:
            raise ValueError(f"{what} DataArray zlib block {k} does not inflate to its declared {usize} bytes "
                             f"(got {len(chunk)}{'' if d.eof else ', stream truncated'})")
        out.append(chunk)
        at += csize
    return b"".join(out)
