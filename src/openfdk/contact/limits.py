"""Limits of the elastic-foundation contact, reported before they bite.

* **Depth band.** Vertices deeper than ``max_depth`` are ignored (they are taken to be
  behind the opposite surface). :func:`warn_depth` warns, once per contact and run,
  when a penetration comes within 10 % of ``max_depth`` (:class:`ContactDepthWarning`),
  except inside :func:`quiet_depth`: there the contacts are evaluated at poses that are
  not poses of the model (the FDK step's model with the contacts exact,
  :mod:`openfdk.fdk.contact_step`).
* **Distance-grid memory.** :func:`grid_estimate` predicts the nodes and the bytes of a
  narrow-band grid before it is built: the box is the surface's bounding box inflated
  by the band half-width w = max_depth + 2h, with n = Π ⌈(extent + 2w)/h⌉ + 1 nodes; the
  grid keeps 17 bytes per node (4 float32 values, a 1-byte cell mask) and the build
  peaks at about :data:`BUILD_BYTES_PER_NODE` bytes per node (float64 work arrays and the
  difference gradient). :func:`check_grid_memory` raises a clear error, naming the mesh
  and the spacing that would fit, when the build would exceed the limit
  (``$OPENFDK_GRID_MEMORY_MB``, default :data:`DEFAULT_LIMIT_MB`), and warns
  (:class:`GridSizeWarning`) before a build of more than :data:`NOTICE_MB`.
"""

from __future__ import annotations

import os
import warnings
from contextlib import contextmanager

import numpy as np

#: peak bytes per grid node while building: float64 φ and gradient, bool marks, float32
#: values, uint8 cells and the difference-gradient temporaries (tracemalloc: 129 B/node
#: for a 1.4 M-node grid; small grids add fixed overheads on top)
BUILD_BYTES_PER_NODE = 128
STORED_BYTES_PER_NODE = 17
DEFAULT_LIMIT_MB = 2048.0
NOTICE_MB = 1024.0
DEPTH_FRACTION = 0.9
#: nesting depth of :func:`quiet_depth` (0: :func:`warn_depth` warns)
_quiet = 0


class ContactDepthWarning(UserWarning):
    """A penetration came within 10 % of the contact's max_depth."""


class GridSizeWarning(UserWarning):
    """A large distance grid is about to be built."""


@contextmanager
def quiet_depth():
    """Hold :func:`warn_depth` back inside the block, where the contacts are evaluated at
    poses that are not poses of the model (a step's model, not a result)."""
    global _quiet
    _quiet += 1
    try:
        yield
    finally:
        _quiet -= 1


def warn_depth(name, max_penetration, max_depth):
    """Warn when ``max_penetration`` (m) ≥ 90 % of ``max_depth`` (m), except inside
    :func:`quiet_depth`. The message does not depend on the depth, so Python's warning
    registry shows it once per contact."""
    if not _quiet and max_penetration >= DEPTH_FRACTION * max_depth:
        warnings.warn(
            f"contact {name!r}: penetration reached {100 * DEPTH_FRACTION:.0f} % of max_depth "
            f"({max_depth * 1e3:g} mm); vertices deeper than max_depth are ignored, so raise max_depth",
            ContactDepthWarning, stacklevel=3)


def grid_estimate(vertices_B, spacing, max_depth):
    """(shape (3,), n_nodes, build_bytes, stored_bytes) of the narrow-band grid of a
    surface with vertices (n, 3) m at ``spacing`` and ``max_depth`` (m)."""
    V = np.asarray(vertices_B, dtype=float)
    width = float(max_depth) + 2.0 * float(spacing)
    extent = V.max(axis=0) - V.min(axis=0) + 2.0 * width
    shape = tuple(int(np.ceil(e / spacing)) + 1 for e in extent)
    n = int(np.prod(shape, dtype=np.int64))
    return shape, n, n * BUILD_BYTES_PER_NODE, n * STORED_BYTES_PER_NODE


def memory_limit_mb():
    """The build limit in MB: ``$OPENFDK_GRID_MEMORY_MB`` or :data:`DEFAULT_LIMIT_MB`."""
    env = os.environ.get("OPENFDK_GRID_MEMORY_MB")
    if env is None:
        return DEFAULT_LIMIT_MB
    try:
        value = float(env)
    except ValueError:
        raise ValueError(f"OPENFDK_GRID_MEMORY_MB must be a number of MB, got {env!r}") from None
    if not value > 0:
        raise ValueError(f"OPENFDK_GRID_MEMORY_MB must be > 0, got {env!r}")
    return value


def _size(n_bytes):
    return f"{n_bytes / 2**30:.1f} GB" if n_bytes >= 2**30 else f"{n_bytes / 2**20:.0f} MB"


def check_grid_memory(mesh_name, vertices_B, spacing, max_depth):
    """Raise ValueError when building the grid would exceed the memory limit (the
    message gives the spacing that fits); warn before a build above NOTICE_MB."""
    shape, n, build, stored = grid_estimate(vertices_B, spacing, max_depth)
    limit = memory_limit_mb() * 2**20
    if build > limit:
        fit = spacing * (build / limit) ** (1.0 / 3.0)
        while grid_estimate(vertices_B, fit, max_depth)[2] > limit:  # the band widens with h too
            fit *= 1.05
        raise ValueError(
            f"distance grid for mesh '{mesh_name}' would need about {_size(build)} to build "
            f"({n:.3g} nodes at spacing {spacing * 1e3:g} mm; limit {limit / 2**20:.0f} MB, "
            f"OPENFDK_GRID_MEMORY_MB): use a larger spacing, grid_spacing >= {np.ceil(fit * 1e5) / 1e2:.2f} mm, "
            "or mesh only the joint region")
    if build > NOTICE_MB * 2**20:
        warnings.warn(
            f"building a distance grid for mesh '{mesh_name}': {n:.3g} nodes, about {build / 2**20:.0f} MB "
            f"while building, {stored / 2**20:.0f} MB kept (spacing {spacing * 1e3:g} mm); it is cached on disk",
            GridSizeWarning, stacklevel=3)
    return shape, n, build, stored


__all__ = ["ContactDepthWarning", "GridSizeWarning", "warn_depth", "quiet_depth", "grid_estimate", "check_grid_memory",
           "memory_limit_mb"]
