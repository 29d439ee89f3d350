"""Distance grids memoised in memory and on disk.

Building the narrow-band grid of a fossa surface takes about a second
(:func:`~.distance_grid.build_distance_grid`); every process that loads a contact model
would pay it — each ``openfdk run``, each Dask worker of a study. Grids are therefore
kept

* in memory, per process (at most :data:`MEMORY_SLOTS`, least recently used dropped);
* on disk, as ``<key>.npz`` files in the cache folder: ``$OPENFDK_CACHE_DIR`` if set,
  else ``$XDG_CACHE_HOME/openfdk`` or ``~/.cache/openfdk``, sub-folder
  ``distance-grids``. ``OPENFDK_CACHE_DIR=off`` turns the disk cache off.

The key is a SHA-1 of the mesh's body-frame vertices and faces, the spacing, the depth
and :data:`GRID_FORMAT` (raised whenever the builder changes its output), so a changed
mesh or setting never meets a stale grid. Files are written under a temporary name and
renamed, so concurrent workers cannot read a half-written grid; a file that cannot be
read is rebuilt and replaced. A grid read from disk is a read-only memory map of the
file's ``values`` member (stored uncompressed), so a run keeps resident only the pages of
the cells it samples — the band around the contact — not the whole grid (≈ 80 MB for a
fossa at the default resolution).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import struct
import warnings
import zipfile
from collections import OrderedDict
from pathlib import Path

import numpy as np

from .distance_grid import SignedDistanceGrid, build_distance_grid
from .mesh import SurfaceMesh

__all__ = ["cached_distance_grid", "clear_grid_cache", "grid_cache_dir", "grid_cache_info"]

GRID_FORMAT = 1
MEMORY_SLOTS = 16
_MEMORY: OrderedDict[str, SignedDistanceGrid] = OrderedDict()


def grid_cache_dir() -> Path | None:
    """The disk cache folder (module docstring), or None when turned off."""
    env = os.environ.get("OPENFDK_CACHE_DIR")
    if env is not None:
        if env.strip().lower() in ("", "0", "off", "none", "false"):
            return None
        return Path(env).expanduser() / "distance-grids"
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "openfdk" / "distance-grids"


def _key(mesh: SurfaceMesh, spacing: float, max_depth: float) -> str:
    digest = hashlib.sha1()
    digest.update(np.ascontiguousarray(mesh.vertices_B, dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    digest.update(np.array([spacing, max_depth, GRID_FORMAT], dtype=np.float64).tobytes())
    return digest.hexdigest()


def _mapped_member(path: Path, name: str):
    """The array ``name`` of the uncompressed ``.npz`` at ``path`` as a read-only memory
    map (np.savez stores members uncompressed), or None if it is compressed. Only the
    pages a run touches — the cells near the contact — become resident."""
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo(f"{name}.npy")
    if info.compress_type != zipfile.ZIP_STORED:
        return None
    with open(path, "rb") as fh:
        fh.seek(info.header_offset)
        local = fh.read(30)  # the member's local file header: name and extra-field lengths at 26
        n_name, n_extra = struct.unpack("<HH", local[26:30])
        fh.seek(info.header_offset + 30 + n_name + n_extra)
        version = np.lib.format.read_magic(fh)
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = read_header(fh)
        offset = fh.tell()
    return np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=shape, order="F" if fortran else "C")


def _read(path: Path, mesh_name: str) -> SignedDistanceGrid:
    with np.load(path) as z:
        values = _mapped_member(path, "values")
        values = z["values"] if values is None else values
        cell_valid, origin = z["cell_valid"], z["origin_B"]
        spacing, max_depth, n_evaluated = float(z["spacing"]), float(z["max_depth"]), int(z["n_evaluated"])
    if values.ndim != 4 or values.shape[3] != 4 or cell_valid.shape != tuple(n - 1 for n in values.shape[:3]):
        raise ValueError("inconsistent array shapes")
    for a in (values, cell_valid, origin):
        a.setflags(write=False)
    return SignedDistanceGrid(values, cell_valid, origin, spacing, max_depth, mesh_name, n_evaluated)


def _write(path: Path, grid: SignedDistanceGrid) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".npz", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, values=grid.values, cell_valid=grid.cell_valid, origin_B=grid.origin_B,
                     spacing=grid.spacing, max_depth=grid.max_depth, n_evaluated=grid.n_evaluated)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def cached_distance_grid(mesh: SurfaceMesh, spacing: float, max_depth: float) -> SignedDistanceGrid:
    """:func:`~.distance_grid.build_distance_grid` of ``mesh`` (spacing, max_depth in
    m), from memory, else from the disk cache, else built (and stored in both).

    Contact pairs that share a surface (e.g. the models of a parameter study) share its
    grid. A disk-cache problem (unwritable folder, unreadable file) only costs a
    rebuild; it is reported as a RuntimeWarning, never an error."""
    key = _key(mesh, float(spacing), float(max_depth))
    grid = _MEMORY.get(key)
    if grid is not None:
        _MEMORY.move_to_end(key)
        return grid
    folder = grid_cache_dir()
    path = None if folder is None else folder / f"{key}.npz"
    if path is not None and path.is_file():
        try:
            grid = _read(path, mesh.name)
        except Exception as exc:  # a damaged cache file: rebuild it
            warnings.warn(f"distance-grid cache file {path} of mesh '{mesh.name}' is unreadable ({exc}); rebuilding",
                          RuntimeWarning, stacklevel=2)
    if grid is None:
        grid = build_distance_grid(mesh, spacing, max_depth)
        if path is not None:
            try:
                _write(path, grid)
            except OSError as exc:
                warnings.warn(f"cannot write the distance-grid cache {path}: {exc}", RuntimeWarning, stacklevel=2)
    _MEMORY[key] = grid
    while len(_MEMORY) > MEMORY_SLOTS:
        _MEMORY.popitem(last=False)
    return grid


def clear_grid_cache(disk: bool = False) -> None:
    """Drop every distance grid held in memory; with ``disk``, also delete the disk
    cache's grid files."""
    _MEMORY.clear()
    folder = grid_cache_dir()
    if disk and folder is not None and folder.is_dir():
        for f in folder.glob("*.npz"):
            f.unlink(missing_ok=True)


def grid_cache_info():
    """(folder or None, number of grid files, total bytes) of the disk cache."""
    folder = grid_cache_dir()
    if folder is None or not folder.is_dir():
        return folder, 0, 0
    files = list(folder.glob("*.npz"))
    return folder, len(files), sum(f.stat().st_size for f in files)
