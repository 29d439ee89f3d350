"""A trial's gait cycles, found from a run's measured loads, and a run's results over
them: mean and standard deviation across the cycles (``openfdk cycles``,
docs/outputs.md#gait-cycles).

One algorithm:

1. **The foot's load.** The measured loads acting on the foot's body B (summary.json's
   ``input.external_loads``: load -> body) are summed as applied at each frame (forces.csv
   ``<load>.external_F{x,y,z}_N``, world), and projected on the up direction
   u = −g/|g| (``input.gravity_W_m_s2``): v(t) = Σ F_W · u (N). A frame without
   the value (a failed frame, a load not known there) has none.
2. **Heel strikes.** Where v rises through the threshold v* (default 20 N) at the end
   of a swing: the time between frames i and i + 1 with v_i < v* ≤ v_{i+1}, by linear
   interpolation, t* = t_i + (v* − v_i) / (v_{i+1} − v_i) (t_{i+1} − t_i), where the
   frames up to i are known and below v* for at least ``min_off`` s (the swing; default
   0.2 s), and the foot then stands: at or above v* for at least ``min_on`` s (default
   0.2 s) in one stretch, before the next swing. Between the crossing and the stance v
   may dip below v* (a foot touching the belt before it loads it); a plate's noise in
   swing, too short for a stance, and a foot whose load is not known are no heel
   strikes.
3. **Cycles.** Consecutive heel strikes [T_k, T_{k+1}]; a frame's % of cycle k is
   p = 100 (t − T_k) / (T_{k+1} − T_k). The cycle's toe-off is where the swing that
   ends at T_{k+1} began, v falling through v* (linear between the two frames): its %
   is the stance's share of the cycle.
4. **The ensemble.** Each quantity of each cycle at p = 0, 1, …, 100 %, interpolated
   linearly between two adjacent usable frames (converged, finite), never across a failed
   frame (:func:`openfdk.analysis.kinematics_validation.interpolate_usable`); at each p
   the mean, the standard deviation (ddof 1, NaN with fewer than two cycles) and the
   number n of cycles with a value.

The quantities: every contact's force magnitude |F| and its regions' forces
(``<contact>.<region>_N``, a knee's medial and lateral compartments), N; every FDK
DOF's value α, in SI (coordinates.csv ``<dof>_m`` / ``_rad`` where the DOF is a
coordinate of an imported model, else forces.csv ``fdk.<dof>.alpha``); and the foot's
vertical load v, N.

Errors are :class:`CycleError` (a ``ValueError``) with a one-line message naming the
result folder and the entry.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..dynamics.results import EXTERNAL_LOAD_KEYS
from .kinematics_validation import interpolate_usable

__all__ = ["CycleError", "Quantity", "Cycles", "foot_load", "gait_events", "heel_strikes", "quantities", "ensemble",
           "gait_cycles", "PERCENT", "DEFAULT_THRESHOLD_N", "DEFAULT_MIN_OFF_S", "DEFAULT_MIN_ON_S"]

#: the cycle's sample points (%)
PERCENT = np.arange(101, dtype=float)
#: the vertical load (N) whose rise through it is a heel strike
DEFAULT_THRESHOLD_N = 20.0
#: the least time (s) the foot is off the ground before a heel strike, and on it after
DEFAULT_MIN_OFF_S = 0.2
DEFAULT_MIN_ON_S = 0.2


class CycleError(ValueError):
    """A run whose gait cycles cannot be found or averaged (one line naming the folder
    and the entry)."""


@dataclass(frozen=True)
class Quantity:
    """One result quantity over the run: ``name`` (the column it comes from), ``kind``
    (``force`` N, ``length`` m, ``angle`` rad), ``values`` (nf,) SI, ``usable`` (nf,)
    bool (converged and finite)."""

    name: str
    kind: str
    values: np.ndarray
    usable: np.ndarray


@dataclass
class Cycles:
    """The cycles of a run and the quantities over them.

    foot: the body B; threshold_N: v*; time (nf,) s and load (nf,) N: v at the frames
    (NaN without a value); strikes (nc + 1,) s: the heel strikes T_k; toe_offs (nc,) s:
    each cycle's toe-off, where its swing began (NaN where not known); per quantity name,
    ``per_cycle[name]`` (nc, 101) at PERCENT (NaN where a cycle has no value) and
    ``kinds[name]``; ``failed`` (nc,) int: the failed frames within each cycle."""

    foot: str
    threshold_N: float
    time: np.ndarray
    load: np.ndarray
    strikes: np.ndarray
    per_cycle: dict = field(default_factory=dict)
    kinds: dict = field(default_factory=dict)
    failed: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    toe_offs: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def stance_percent(self):
        """(nc,) %: each cycle's toe-off in % of the cycle (NaN where not known)."""
        T = np.asarray(self.strikes, float)
        return 100.0 * (np.asarray(self.toe_offs, float) - T[:-1]) / (T[1:] - T[:-1])

    @property
    def n_cycles(self) -> int:
        return max(len(self.strikes) - 1, 0)

    def mean(self, name):
        """(101,) the mean over the cycles at PERCENT (NaN where no cycle has a value)."""
        return _stats(self.per_cycle[name])[0]

    def sd(self, name):
        """(101,) the standard deviation (ddof 1) over the cycles at PERCENT."""
        return _stats(self.per_cycle[name])[1]

    def count(self, name):
        """(101,) int: the cycles with a value at each PERCENT."""
        return _stats(self.per_cycle[name])[2]


def _stats(table):
    table = np.asarray(table, float)
    n = np.sum(np.isfinite(table), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, np.nansum(table, axis=0) / np.maximum(n, 1), np.nan)
        dev = np.where(np.isfinite(table), table - mean, 0.0)
        sd = np.where(n > 1, np.sqrt(np.sum(dev * dev, axis=0) / np.maximum(n - 1, 1)), np.nan)
    return mean, sd, n


def foot_load(results, foot):
    """v (nf,) N: the vertical measured load on body ``foot`` at the run's frames, NaN
    where a frame has none (module docstring, step 1). CycleError when the run has no
    measured loads on that body."""
    where = results.directory or "the run"
    record = results.summary.get("input") or {}
    loads, gravity = record.get("external_loads"), record.get("gravity_W_m_s2")
    if results.forces is None or not isinstance(loads, dict) or not loads:
        raise CycleError(f"{where}: no measured loads in summary.json (input.external_loads): a run with --external-loads "
                         "(or a model file's external_loads) records them")
    bodies = sorted({str((v or {}).get("body")) for v in loads.values() if isinstance(v, dict)})
    names = [k for k, v in loads.items() if isinstance(v, dict) and v.get("body") == foot]
    if not names:
        raise CycleError(f"{where}: --foot {foot!r}: no measured load acts on it; the loads act on {', '.join(bodies)}")
    try:
        g = np.asarray(gravity if gravity is not None else [], float).reshape(-1)
    except (TypeError, ValueError):
        g = np.zeros(0)
    if g.shape != (3,) or not np.all(np.isfinite(g)) or np.linalg.norm(g) == 0:
        raise CycleError(f"{where}: summary.json: input.gravity_W_m_s2 must be 3 finite numbers, not all zero, "
                         f"got {gravity!r}")
    up = -g / np.linalg.norm(g)
    v = np.zeros(len(results.forces))
    for name in names:
        columns = [f"{name}.{key}" for key in EXTERNAL_LOAD_KEYS[:3]]
        missing = [c for c in columns if c not in results.forces.columns]
        if missing:
            raise CycleError(f"{where}: forces.csv: no column {missing[0]!r} for the measured load {name!r}")
        F = results.forces[columns].to_numpy(float)
        v = v + F @ up
    converged = results.forces["converged"].to_numpy() == 1
    return np.where(converged & np.isfinite(v), v, np.nan)


def _runs(mask):
    """[(first, last)] frame indices of each stretch of consecutive True in ``mask``."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1))


def gait_events(time, load, threshold=DEFAULT_THRESHOLD_N, min_off=DEFAULT_MIN_OFF_S, min_on=DEFAULT_MIN_ON_S):
    """(strikes (k,) s, toe_offs (k,) s) of a foot whose vertical load is ``load`` (nf,)
    N at ``time`` (nf,) s, NaN where not known (module docstring, step 2). Each heel
    strike is the crossing at the end of a swing (frames known and below the threshold
    for at least ``min_off`` s) whose foot then stands (at or above it for at least
    ``min_on`` s in one stretch) before the next swing. The load may chatter about the
    threshold between the two: a foot that touches the belt lightly before it loads it
    (DM's ``tm_set1``, 15.4 s). ``toe_offs[k]`` is the crossing where that swing began,
    the load falling through the threshold (NaN where the swing began at the first
    frame or after one not known)."""
    t, v = np.asarray(time, float), np.asarray(load, float)
    known = np.isfinite(v)
    on = known & (v >= threshold)
    off = known & (v < threshold)
    swings = [(a, b) for a, b in _runs(off) if t[b] - t[a] >= min_off - 1e-9]
    stances = [a for a, b in _runs(on) if t[b] - t[a] >= min_on - 1e-9]
    strikes, toe_offs = [], []
    for k, (a, i) in enumerate(swings):
        if i + 1 >= len(t) or not on[i + 1]:  # the swing ends at the trial's end or in a frame not known
            continue
        next_swing = swings[k + 1][0] if k + 1 < len(swings) else len(t)
        if not any(i + 1 <= s < next_swing for s in stances):
            continue
        strikes.append(_crossing(t, v, threshold, i))
        toe_offs.append(_crossing(t, v, threshold, a - 1) if a > 0 and on[a - 1] else np.nan)
    return np.asarray(strikes, float), np.asarray(toe_offs, float)


def _crossing(t, v, threshold, i):
    """The time (s) where v passes ``threshold`` between frames i and i + 1 (linear)."""
    return t[i] + (threshold - v[i]) / (v[i + 1] - v[i]) * (t[i + 1] - t[i])


def heel_strikes(time, load, threshold=DEFAULT_THRESHOLD_N, min_off=DEFAULT_MIN_OFF_S, min_on=DEFAULT_MIN_ON_S):
    """(k,) s: the heel strikes of :func:`gait_events`."""
    return gait_events(time, load, threshold, min_off, min_on)[0]


def quantities(results):
    """[Quantity]: the contacts' |F| and regions (N) and the FDK DOFs' α (SI) of the run
    (module docstring)."""
    f = results.forces
    converged = f["converged"].to_numpy() == 1
    out = []

    def columns(*names):
        missing = [n for n in names if n not in f.columns]
        if missing:
            raise CycleError(f"{results.directory or 'the run'}: forces.csv: no column {missing[0]!r}")
        return f[list(names)].to_numpy(float)

    def add(name, kind, values):
        values = np.asarray(values, float)
        out.append(Quantity(name, kind, values, converged & np.isfinite(values)))

    for contact in results.contacts():
        F = columns(*(f"{contact}.F{c}_N" for c in "xyz"))
        add(f"{contact}.|F|_N", "force", np.linalg.norm(F, axis=1))
        prefix = f"{contact}."
        for column in f.columns:
            region = column[len(prefix):-2] if column.startswith(prefix) and column.endswith("_N") else None
            if region and region not in ("Fx", "Fy", "Fz"):
                add(column, "force", columns(column)[:, 0])
    coordinates = results.coordinates
    for dof in results.fdk_dofs():
        for suffix, kind in (("_m", "length"), ("_rad", "angle")):
            if coordinates is not None and f"{dof}{suffix}" in coordinates.columns:
                add(f"{dof}{suffix}", kind, coordinates[f"{dof}{suffix}"].to_numpy(float))
                break
        else:
            add(f"fdk.{dof}.alpha", "1", columns(f"fdk.{dof}.alpha")[:, 0])
    return out


def ensemble(time, strikes, values, usable):
    """(nc, 101): ``values`` (nf,) over each cycle [T_k, T_{k+1}] of ``strikes`` at
    PERCENT, NaN where not interpolated between usable frames (module docstring,
    steps 3–4)."""
    t = np.asarray(time, float)
    rows = []
    for T0, T1 in zip(strikes[:-1], strikes[1:]):
        at = T0 + PERCENT / 100.0 * (T1 - T0)
        value, _ = interpolate_usable(t, values, usable, at)
        rows.append(value)
    return np.asarray(rows, float).reshape(len(rows), len(PERCENT))


def gait_cycles(results, foot, threshold=DEFAULT_THRESHOLD_N, min_off=DEFAULT_MIN_OFF_S, min_on=DEFAULT_MIN_ON_S):
    """The :class:`Cycles` of a run (a RunResults) for the foot body ``foot``."""
    where = results.directory or "the run"
    if not (np.isfinite(threshold) and threshold > 0):
        raise CycleError(f"--threshold: must be a positive force in N, got {threshold:g}")
    for flag, value in (("--min-off", min_off), ("--min-on", min_on)):
        if not (np.isfinite(value) and value >= 0):
            raise CycleError(f"{flag}: must be a time >= 0 s, got {value:g}")
    load = foot_load(results, foot)
    time = np.asarray(results.forces.index.to_numpy(), float)
    strikes, toe_offs = gait_events(time, load, threshold, min_off, min_on)
    if len(strikes) < 2:
        peak = np.nanmax(load) if np.any(np.isfinite(load)) else float("nan")
        raise CycleError(f"{where}: --foot {foot!r}: {len(strikes)} heel strike(s) (its vertical load rising through "
                         f"{threshold:g} N after {min_off:g} s below it; its peak is {peak:.4g} N): a cycle needs two")
    # the toe-off of cycle k begins the swing that ends at heel strike k + 1
    toe = toe_offs[1:]
    toe = np.where((toe > strikes[:-1]) & (toe < strikes[1:]), toe, np.nan)
    cycles = Cycles(foot, float(threshold), time, load, strikes, toe_offs=toe)
    converged = results.forces["converged"].to_numpy() == 1
    cycles.failed = np.array([int(np.sum(~converged & (time >= T0) & (time <= T1)))
                              for T0, T1 in zip(strikes[:-1], strikes[1:])], int)
    for q in quantities(results) + [Quantity(f"{foot}.vertical_load_N", "force", load, np.isfinite(load))]:
        cycles.per_cycle[q.name] = ensemble(time, strikes, q.values, q.usable)
        cycles.kinds[q.name] = q.kind
    return cycles


def csv_text(cycles: Cycles) -> str:
    """cycles.csv: ``percent``, then per quantity ``<name>.mean``, ``<name>.sd`` (SI: N,
    m, rad) and ``<name>.n`` at each PERCENT."""
    names = list(cycles.per_cycle)
    header = ["percent"] + [f"{n}.{s}" for n in names for s in ("mean", "sd", "n")]
    stats = {n: _stats(cycles.per_cycle[n]) for n in names}
    lines = [",".join(header)]
    for i, p in enumerate(PERCENT):
        row = [f"{p:g}"]
        for n in names:
            mean, sd, count = stats[n]
            row += [_number(mean[i]), _number(sd[i]), str(int(count[i]))]
        lines.append(",".join(row))
    return "\n".join(lines) + "\n"


def strikes_text(cycles: Cycles) -> str:
    """cycles_list.csv: one row per cycle: ``cycle`` (1, 2, …), ``start_s``, ``end_s``
    (the heel strikes), ``duration_s``, ``toe_off_s`` and ``stance_percent`` (its
    toe-off, in s and in % of the cycle; empty where not known) and ``failed_frames``
    within it."""
    lines = ["cycle,start_s,end_s,duration_s,toe_off_s,stance_percent,failed_frames"]
    stance = cycles.stance_percent
    for k, (T0, T1) in enumerate(zip(cycles.strikes[:-1], cycles.strikes[1:])):
        toe = "" if not np.isfinite(cycles.toe_offs[k]) else f"{cycles.toe_offs[k]:.6f}"
        lines.append(f"{k + 1},{T0:.6f},{T1:.6f},{T1 - T0:.6f},{toe},{_number(stance[k])},"
                     f"{int(cycles.failed[k])}")
    return "\n".join(lines) + "\n"


def _number(x):
    return "" if not np.isfinite(x) else repr(float(x))


def write_cycles(cycles: Cycles, out_dir, figure=None) -> list:
    """Write cycles.csv, cycles_list.csv and, given a matplotlib ``figure``, cycles.png
    into ``out_dir`` (created; a symbolic link at one of these names is refused, an
    earlier file replaced). Returns the paths written."""
    from ..io.outdir import png_bytes, write_files

    files = [("cycles.csv", csv_text(cycles).encode("utf-8")), ("cycles_list.csv", strikes_text(cycles).encode("utf-8"))]
    if figure is not None:
        files.append(("cycles.png", png_bytes(figure)))
    return write_files(out_dir, files, CycleError)
