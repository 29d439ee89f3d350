"""Contact meshes checked before a run: what ``openfdk check`` prints and ``run`` refuses.

For each contact pair, at the model's reference pose, each of the two meshes X (the
vertex surface A and the opposite surface B) is measured against the other one, Y:

* **triangle count** and **area spread**: the smallest, median and largest triangle
  area (m²) and max/min (a spread of tens is normal for a CAD export; a few huge
  triangles in a fine mesh make the elastic-foundation pressure coarse where they lie);
* **slivers**: triangles whose smallest corner angle is below :data:`SLIVER_DEG`
  (exactly degenerate triangles were already removed, with a warning, when the mesh
  was loaded);
* the **contact zone**: X's triangles whose centroid c lies within
  z = min(max_depth, :data:`ZONE_DISTANCE`) of Y (unsigned distance |c − p|, p the
  closest point of Y, libigl);
* **normals facing away** from Y in the zone: the share of zone triangles, by area,
  with n_X · (p − c) < 0 (the triangle's normal points away from the closest point of
  Y), and the share **aligned** with Y's normal ∇φ_Y at p (n_X · ∇φ_Y > 0). Surfaces
  that face each other give 0 and 0; where they interpenetrate at the reference pose
  p − c turns round on both meshes alike, so *away* counts those triangles too, while
  *aligned* does not;
* **open boundary edges** (edges of one triangle) and how many of them have their
  midpoint in the zone (a rim where the other surface presses: loads are cut off there,
  docs/contact.md "Open meshes").

And the pair's **layer data**: the linear law's pressure modulus (the thickness is folded
into it), or the non-linear law's layers, whose total thickness Σh must exceed the
depth band max_depth (deeper vertices would be beyond the layer).

What refuses the model (``check`` and ``run`` exit 2, one line naming the model file,
the contact and the mesh): inverted normals (:func:`_inverted`: aligned over at least
half of a zone → the mesh with the larger *away* share; fix: ``flip_normals: true``).
Opposed normals that both face away over half their zones are only a warning: locally,
two meshes that overlap at the reference pose look exactly like two separated meshes
that are both wound the other way (flipping both normals swaps inside and outside), so
the check cannot tell which; the same holds for one mesh judged alone. Everything else
is a warning: printed, and kept in summary.json (``input.contact_meshes``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .mesh import SurfaceMesh
from .rim import rim_edges
from .signed_distance import OpenSurfaceDistance

__all__ = ["MeshFigures", "PairCheck", "check_pair", "check_contacts", "table", "ZONE_DISTANCE"]

#: largest distance (m) from the opposing mesh of the contact zone (and at most max_depth)
ZONE_DISTANCE = 5e-3
#: share of the zone (by area) whose normals face away above which the mesh is refused
AWAY_REFUSE = 0.9
#: ... and above which a warning is given
AWAY_WARN = 0.1
#: fewest zone triangles for the facing test to decide anything
MIN_ZONE_TRIANGLES = 10
#: more triangles than this is a warning (a slow grid build, no gain in accuracy)
MANY_TRIANGLES = 100_000
#: largest/median triangle area above which a mesh is flagged as unevenly meshed
AREA_SPREAD_WARN = 100.0
#: smallest corner angle (degrees) of a sliver triangle
SLIVER_DEG = 1.0


@dataclass(frozen=True)
class MeshFigures:
    """One mesh of a pair measured against the other at the reference pose (SI units).

    role : "vertices" (A) or "surface" (B). name : the mesh's file name.
    n_triangles : int. area_min, area_median, area_max : m² (triangle areas).
    n_slivers : int. n_open_edges : int, boundary edges; n_open_in_zone : of them, with
    the midpoint within ``zone`` m of the other mesh; rim_distance : m, the nearest
    boundary-edge midpoint's distance to the other mesh (inf: a closed mesh).
    n_zone : triangles in the zone.
    away_fraction : share of the zone's area whose normals face away (NaN: empty zone).
    aligned_fraction : share of the zone's area whose normals point the same way as the
    other mesh's normal at the closest point (NaN: empty zone).
    """

    role: str
    name: str
    n_triangles: int
    area_min: float
    area_median: float
    area_max: float
    n_slivers: int
    n_open_edges: int
    n_open_in_zone: int
    rim_distance: float
    n_zone: int
    away_fraction: float
    aligned_fraction: float

    @property
    def area_ratio(self) -> float:
        """Largest over smallest triangle area."""
        return self.area_max / self.area_min if self.area_min > 0 else float("inf")

    def as_dict(self):
        return {"role": self.role, "mesh": self.name, "triangles": self.n_triangles,
                "area_min_mm2": self.area_min * 1e6, "area_median_mm2": self.area_median * 1e6,
                "area_max_mm2": self.area_max * 1e6, "area_ratio": self.area_ratio, "slivers": self.n_slivers,
                "open_edges": self.n_open_edges, "open_edges_in_zone": self.n_open_in_zone,
                "rim_distance_mm": None if np.isinf(self.rim_distance) else self.rim_distance * 1e3,
                "zone_triangles": self.n_zone,
                "normals_away_fraction": None if np.isnan(self.away_fraction) else self.away_fraction,
                "normals_aligned_fraction": None if np.isnan(self.aligned_fraction) else self.aligned_fraction}


@dataclass(frozen=True)
class PairCheck:
    """The check of one contact: its two meshes' figures, the zone width (m), the layer
    data in words, and its warnings and refusals (one line each, naming the contact)."""

    contact: str
    meshes: tuple
    zone: float
    layer: str
    warnings: tuple = field(default=())
    errors: tuple = field(default=())

    def as_dict(self):
        return {"contact": self.contact, "zone_mm": self.zone * 1e3, "layer": self.layer,
                "meshes": [m.as_dict() for m in self.meshes], "warnings": list(self.warnings),
                "errors": list(self.errors)}


def _triangle_areas_and_angles(V, F):
    """Areas (m,) m² and smallest corner angles (m,) rad of the triangles F of V."""
    P = V[F]
    areas = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    smallest = np.full(len(F), np.pi)
    for k in range(3):
        e1 = P[:, (k + 1) % 3] - P[:, k]
        e2 = P[:, (k + 2) % 3] - P[:, k]
        norms = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
        cos = np.einsum("ij,ij->i", e1, e2) / np.maximum(norms, 1e-300)
        smallest = np.minimum(smallest, np.arccos(np.clip(cos, -1.0, 1.0)))
    return areas, smallest


def mesh_figures(role, mesh: SurfaceMesh, R_YX, p_YX, other: OpenSurfaceDistance, zone) -> MeshFigures:
    """Figures of ``mesh`` X against the other mesh Y (its distance query ``other``).

    R_YX (3, 3), p_YX (3,) m: X's frame in Y's frame (y = R_YX x + p_YX); zone : m.
    """
    V, F = mesh.vertices_B, mesh.faces
    areas, smallest = _triangle_areas_and_angles(V, F)
    # zone: centroids within `zone` of Y; facing: n_X · (p − c) < 0
    c_Y = V[F].mean(axis=1) @ R_YX.T + p_YX
    _, grad_Y, _, p = other.query(c_Y)
    to_other = p - c_Y
    dist = np.linalg.norm(to_other, axis=1)
    in_zone = dist <= zone
    n_Y = mesh.face_normals_B @ R_YX.T
    decided = in_zone & (dist > 1e-9)
    away = decided & (np.einsum("ij,ij->i", n_Y, to_other) < 0.0)
    aligned = decided & (np.einsum("ij,ij->i", n_Y, grad_Y) > 0.0)
    zone_area = areas[decided].sum()
    enough = decided.sum() >= MIN_ZONE_TRIANGLES
    fraction = float(areas[away].sum() / zone_area) if enough else float("nan")
    aligned_fraction = float(areas[aligned].sum() / zone_area) if enough else float("nan")
    rim = rim_edges(F)
    if len(rim):
        mid_Y = 0.5 * (V[rim[:, 0]] + V[rim[:, 1]]) @ R_YX.T + p_YX
        _, _, _, q = other.query(mid_Y)
        rim_dist = np.linalg.norm(q - mid_Y, axis=1)
        n_rim_zone, rim_distance = int(np.sum(rim_dist <= zone)), float(rim_dist.min())
    else:
        n_rim_zone, rim_distance = 0, float("inf")
    return MeshFigures(role, mesh.name, int(len(F)), float(areas.min()), float(np.median(areas)),
                       float(areas.max()), int(np.sum(smallest < np.radians(SLIVER_DEG))), int(len(rim)),
                       n_rim_zone, rim_distance, int(in_zone.sum()), fraction, aligned_fraction)


def _layer(pair):
    """(layer data in words, warnings) of an ElasticFoundation's pressure law."""
    v = getattr(pair, "variable", None)
    if v is not None:  # thickness from the bones behind the cartilage (contact/thickness.py)
        fields = [f"{side} {1e3 * h.min():.2g}–{1e3 * h.max():.2g} mm" for side, h in
                  (("vertices", v.h_A), ("surface", None if v.h_B is None else v.h_B.h)) if h is not None]
        text = (f"{'nonlinear' if v.nonlinear else 'linear'}, {len(v.K)} layer(s) of variable thickness "
                f"({', '.join(fields)}), {pair.pressure_modulus:.3g} N/m³ at the mean thickness")
        if not v.nonlinear:
            return text, []
        total = v.total_thickness()  # (the thickest the layers get: a depth past it is past every vertex's)
    elif pair.layers is None:
        return f"linear, {pair.pressure_modulus:.3g} N/m³", []
    else:
        total = float(pair.layers[:, 1].sum())
        text = f"nonlinear, {len(pair.layers)} layer(s), h = {total * 1e3:g} mm"
    if pair.max_depth >= total:
        return text, [f"max_depth {pair.max_depth * 1e3:g} mm is not below the layers' thickness "
                      f"{total * 1e3:g} mm: depths beyond the layer are counted (the law continues linearly there)"]
    return text, []


def _where(contact, fig):
    return f"contacts.{contact}.{fig.role} (mesh '{fig.name}')"


_FLIP = "the file is wound the other way: set flip_normals: true (or flip the file's triangles)"


def _inverted(fig_A, fig_B, zone):
    """([(figures, reason)] of the meshes whose normals are inverted in the zone,
    [(figures, warning)] of the meshes that may be).

    Normals that point the same way as the other mesh's (aligned ≥ ½) mean one mesh is
    inverted: the one whose normals face away from the other over more of its zone
    (interpenetration turns the test round on both meshes alike): refused. Opposed
    normals that both face away (≥ ½ each), or one mesh judged alone (the other's zone
    too small) facing away (≥ :data:`AWAY_REFUSE`), are either an overlap at the
    reference pose or inverted files (module docstring): warned.
    """
    figs = [f for f in (fig_A, fig_B) if not np.isnan(f.away_fraction)]
    text = {f.role: (f"the normals of {100 * f.away_fraction:.0f} % of its contact zone ({f.n_zone} triangles "
                     f"within {zone * 1e3:g} mm of the other mesh) face away from it") for f in figs}
    maybe = ("; either the meshes overlap at the reference pose or the file is wound the other way (then set "
             "flip_normals: true)")
    if len(figs) == 1:
        return [], ([(figs[0], text[figs[0].role] + maybe)] if figs[0].away_fraction >= AWAY_REFUSE else [])
    if not figs:
        return [], []
    if max(fig_A.aligned_fraction, fig_B.aligned_fraction) >= 0.5:
        worse = fig_A if fig_A.away_fraction >= fig_B.away_fraction else fig_B
        return [(worse, f"{text[worse.role]}: {_FLIP}")], []
    if min(fig_A.away_fraction, fig_B.away_fraction) >= 0.5:
        return [], [(f, text[f.role] + maybe) for f in figs]
    return [], []


def check_pair(name, pair, R_Wa, p_Wa, R_Wb, p_Wb) -> PairCheck:
    """Check the meshes of the ElasticFoundation ``pair`` (contact ``name``) with body a
    at (R_Wa (3, 3), p_Wa (3,) m) and body b at (R_Wb, p_Wb)."""
    A, B = pair.surface_A, pair.surface_B
    zone = min(pair.max_depth, ZONE_DISTANCE)
    R_ba = R_Wb.T @ R_Wa
    p_ba = R_Wb.T @ (p_Wa - p_Wb)
    fig_A = mesh_figures("vertices", A, R_ba, p_ba, OpenSurfaceDistance(B), zone)
    fig_B = mesh_figures("surface", B, R_ba.T, -R_ba.T @ p_ba, OpenSurfaceDistance(A), zone)
    layer, warn = _layer(pair)
    inverted, doubtful = _inverted(fig_A, fig_B, zone)
    errors = [f"{_where(name, f)}: {why}" for f, why in inverted]
    warn += [f"{_where(name, f)}: {why}" for f, why in doubtful]
    for fig, other in ((fig_A, fig_B), (fig_B, fig_A)):
        where = _where(name, fig)
        if np.isnan(fig.away_fraction):
            warn.append(f"{where}: fewer than {MIN_ZONE_TRIANGLES} triangles within {zone * 1e3:g} mm of "
                        f"'{other.name}' at the reference pose: normals there not checked")
        elif not errors and fig.aligned_fraction >= AWAY_WARN:
            warn.append(f"{where}: over {100 * fig.aligned_fraction:.0f} % of the contact zone its normals point "
                        f"the same way as those of '{other.name}' (mixed winding or a folded mesh)")
        # open edges in the zone are figures (check's table, summary.json), not a warning:
        # an open cap near its partner is a normal design, and the run warns when the
        # contact does reach a rim (contact/rim.py), frame by frame
        if fig.n_triangles > MANY_TRIANGLES:
            warn.append(f"{where}: {fig.n_triangles} triangles (over {MANY_TRIANGLES}): the distance grid builds "
                        "slowly and the results do not gain; decimate the mesh")
        if fig.area_max > AREA_SPREAD_WARN * fig.area_median:
            warn.append(f"{where}: its largest triangle ({fig.area_max * 1e6:.3g} mm²) is over "
                        f"{AREA_SPREAD_WARN:g} times the median ({fig.area_median * 1e6:.3g} mm²): the pressure is "
                        "coarse where the large triangles lie; remesh evenly")
    return PairCheck(name, (fig_A, fig_B), zone, layer, tuple(warn), tuple(errors))


def check_contacts(model) -> list:
    """:func:`check_pair` for every contact of ``model`` at its reference pose."""
    if not model.contacts:
        return []
    state = model.initial_state()
    return [check_pair(c.name, c.pair, state.R_WB[c.body_a], state.p_WB[c.body_a], state.R_WB[c.body_b],
                       state.p_WB[c.body_b]) for c in model.contacts]


def table(checks) -> list:
    """Printable lines: one row per mesh of each checked pair."""
    if not checks:
        return []
    head = (f"  {'contact':<16} {'role':<8} {'mesh':<28} {'triangles':>9} {'area min/med/max mm²':>24} "
            f"{'max/min':>8} {'slivers':>7} {'open':>6} {'in zone':>7} {'zone':>6} {'away':>6} {'aligned':>7}  layer")
    lines = ["  contact meshes at the reference pose (zone: triangles within min(max_depth, "
             f"{ZONE_DISTANCE * 1e3:g} mm) of the other mesh; away: its share facing away from it; aligned: its share "
             "whose normals point like the other mesh's)", head]
    for chk in checks:
        for k, m in enumerate(chk.meshes):
            areas = f"{m.area_min * 1e6:.3g}/{m.area_median * 1e6:.3g}/{m.area_max * 1e6:.3g}"
            away = "-" if np.isnan(m.away_fraction) else f"{100 * m.away_fraction:.0f} %"
            aligned = "-" if np.isnan(m.aligned_fraction) else f"{100 * m.aligned_fraction:.0f} %"
            name = m.name if len(m.name) <= 28 else "…" + m.name[-27:]
            lines.append(f"  {chk.contact if k == 0 else '':<16} {m.role:<8} {name:<28} {m.n_triangles:>9} "
                         f"{areas:>24} {m.area_ratio:>8.3g} {m.n_slivers:>7} {m.n_open_edges:>6} "
                         f"{m.n_open_in_zone:>7} {m.n_zone:>6} {away:>6} {aligned:>7}  {chk.layer if k == 0 else ''}")
    return lines
