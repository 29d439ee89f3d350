"""Figures of any run (``openfdk plot RESULT_DIR``, and at the end of ``openfdk run``).

One PNG per topic, each only when the run has something to show:

* ``kinematics.png`` — for a model with joint coordinates (an OpenSim model), the
  coordinates grouped by joint (deg, mm: as OpenSim's ``.mot``); otherwise every body's
  centre-of-mass position (mm) and orientation (body-fixed x-y-z Cardan angles of R_WB,
  deg), both relative to the world frame W;
* ``fdk_dofs.png`` — FDK DOF values α and residual forces f^FDK (paper Eqs. 14–17);
* ``measures.png`` — chosen kinematic measures evaluated on the tracked poses;
* ``muscles.png`` — muscle forces (N) and activations f/s;
* ``ligaments.png`` — ligament and spring forces;
* ``actuators.png`` — reserve and residual actuators' forces (N or N·m) and controls
  τ/F, with the residual-force threshold (5 % of the body weight);
* ``contact.png`` — contact force (world components and magnitude), centre of pressure
  (world) and contact area;
* ``reactions.png`` — joint and constraint reactions, grouped by unit;
* ``joint_loads.png`` — for a model with joint coordinates, the magnitude of the force
  and of the moment each joint transmits to its child body (OpenSim's JointReaction;
  the force in body weights when summary.json gives the body weight);
* ``joint_reaction.png`` — with the model file's ``joint_reaction`` section, each
  report's force components in its frame (the knee's force along the tibia);
* ``moment_arms.png`` — with ``--moment-arms``, each muscle's moment arm against the
  value of each coordinate it spans (the coordinates most muscles span);
* ``convergence.png`` — per-frame iterations and residuals of each stage.

Failed frames are shaded red in every figure (and marked × in the convergence figure).
Every axis names its quantity, unit and frame; each figure's caption states the sign
conventions (docs/outputs.md has the full reference).  Figures are plain matplotlib
``Figure`` objects, not registered with pyplot: no display or backend is needed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.joint_load_outputs import joint_load_bases
from ..results.run import conjugate_unit, measure_unit
from .layout import stack_layout

__all__ = ["figure_plan", "iter_figures", "make_figures", "save_figures", "DISPLAY"]

#: measure kind -> (display factor from SI, display unit)
DISPLAY = {"length": (1e3, "mm"), "angle": (180.0 / np.pi, "deg"), "1": (1.0, "–")}
MAX_LEGEND = 12
MAX_DEFAULT_MEASURES = 6
TIME_LABEL = "time (s)"


#: a measure component whose range is below this fraction of max(1, |value|) (SI) is
#: round-off around a constant (a constrained measure): not drawn, named constant
CONSTANT_RTOL = 1e-9
CAPTION_FONTSIZE = 7
#: the gap above a figure's title (in); 2 % of a one-panel figure's 3.2 in
TITLE_TOP_IN = 0.07
#: the drawing cost, in axes, :func:`figure_plan` expects of a figure other than the body poses'
FIGURE_WEIGHT = 4


def line_styles(n):
    """n distinct (colour, line style) pairs: tab10 colours up to 10 lines, tab20 up to 20,
    then tab20 with solid, dashed, dotted and dash-dot lines (80 pairs), then a sampled
    colour map — no two lines of a panel look alike."""
    from matplotlib import colormaps

    if n <= 10:
        return [(colormaps["tab10"](i), "-") for i in range(n)]
    if n <= 20:
        return [(colormaps["tab20"](i), "-") for i in range(n)]
    dashes = ("-", "--", ":", "-.")
    if n <= 80:
        return [(colormaps["tab20"](i % 20), dashes[i // 20]) for i in range(n)]
    cmap = colormaps["turbo"]
    return [(cmap(i / (n - 1)), dashes[i % 4]) for i in range(n)]


def _is_constant(values):
    """True when the finite ``values`` (SI) vary by less than round-off."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return False
    return float(np.ptp(v)) <= CONSTANT_RTOL * max(1.0, float(np.max(np.abs(v))))


def _constant_entry(ax, label, value, unit):
    """A legend entry (no line) for a component that is constant: not drawn as noise."""
    value = 0.0 if abs(value) < 1e-6 else value  # round-off around zero (display units) shown as 0
    ax.plot([], [], " ", label=f"{label}: constant {value:.4g} {unit}".rstrip())


def _figure(n_rows, title, width=11.0, row_height=2.3):
    """A stand-alone matplotlib Figure (not registered with pyplot: no backend is chosen
    and nothing stays open; a notebook still displays it) with n_rows shared-x axes."""
    from matplotlib.figure import Figure

    height = 0.9 + row_height * n_rows
    fig = Figure(figsize=(width, height))
    axes = list(fig.subplots(n_rows, 1, sharex=True, squeeze=False)[:, 0])
    # the title TITLE_TOP_IN below the top edge in every figure (matplotlib's default, 2 %
    # of the height, left half an inch of blank above a 26-inch figure's title)
    fig.suptitle(title, fontsize=11, y=1.0 - TITLE_TOP_IN / height)
    axes[-1].set_xlabel(TIME_LABEL)
    for ax in axes[:-1]:
        ax.set_xlabel(TIME_LABEL)
        ax.xaxis.label.set_visible(False)
    return fig, axes


def _finish(fig, axes, t, failed, caption):
    """Shade failed frames, add the caption, lay out."""
    if len(t) > 1 and failed.any():
        half = 0.5 * float(np.min(np.diff(t)))
        for ax in axes:
            for i in np.flatnonzero(failed):
                ax.axvspan(t[i] - half, t[i] + half, color="red", alpha=0.15, lw=0)
    for ax in axes:
        ax.grid(True, lw=0.3, alpha=0.5)
        if ax.get_legend_handles_labels()[0]:
            handles, labels = ax.get_legend_handles_labels()
            ax.legend(handles[:MAX_LEGEND], labels[:MAX_LEGEND], loc="upper left", bbox_to_anchor=(1.01, 1.0),
                      fontsize=7, borderaxespad=0.0)
    text = caption + (" Red bands: failed frames." if failed.any() else "")
    # wrapped here, at a width in characters that fits the figure, so that the room left
    # for it below the axes is known in inches (matplotlib's own wrap is done at draw time)
    import textwrap

    width_in, height_in = fig.get_size_inches()
    per_line = int(0.96 * width_in * 72.0 / (0.56 * CAPTION_FONTSIZE))
    lines = textwrap.wrap(text, per_line)
    fig.text(0.01, 0.06 / height_in, "\n".join(lines), fontsize=CAPTION_FONTSIZE, va="bottom", ha="left")
    caption_in = len(lines) * 1.25 * CAPTION_FONTSIZE / 72.0 + 0.12  # the caption's lines and margins
    # the axes fixed where the measured decorations fit (plots/layout.py: a third of the
    # time to save a figure went to constrained layout)
    return stack_layout(fig, axes, caption_in)


def _failed(results):
    failed = results.kinematics["converged"].to_numpy() == 0
    if results.forces is not None:
        failed = failed | (results.forces["converged"].to_numpy() == 0)
    return failed


def _col(df, name):
    return df[name].to_numpy(dtype=float)


# ---------------------------------------------------------------------------- figures
def _kinematics(results, t, failed):
    from ..numerics.spatial import rotation_matrix, xyz_angles_from_matrix

    bodies = results.bodies()
    fig, axes = _figure(2 * len(bodies), f"{_name(results)}: body poses")
    k = results.kinematics
    for b, name in enumerate(bodies):
        ax_p, ax_r = axes[2 * b], axes[2 * b + 1]
        for c in "xyz":
            r = _col(k, f"{name}.{c}_m")
            finite = np.flatnonzero(np.isfinite(r))
            r0 = r[finite[0]] if finite.size else 0.0
            if _is_constant(r):
                _constant_entry(ax_p, c, 1e3 * r0, "mm")
            else:  # displacement from the first frame: millimetres stay visible in a lab frame
                ax_p.plot(t, 1e3 * (r - r0), label=f"{c} (from {1e3 * r0:.1f} mm)")
        quat = np.column_stack([_col(k, f"{name}.e{j}") for j in range(4)])
        angles = np.full((len(t), 3), np.nan)
        for i, q in enumerate(quat):
            if np.all(np.isfinite(q)):
                angles[i] = xyz_angles_from_matrix(rotation_matrix(q / np.linalg.norm(q)))
        missing = ~np.isfinite(angles)
        angles = np.degrees(np.unwrap(np.where(missing, 0.0, angles), axis=0))
        angles[missing] = np.nan
        for j, c in enumerate(("about x", "about y'", "about z''")):
            if _is_constant(np.radians(angles[:, j])):
                _constant_entry(ax_r, c, angles[np.isfinite(angles[:, j]), j][0], "deg")
            else:
                ax_r.plot(t, angles[:, j], label=c)
        ax_p.set_ylabel(f"{name} COM displacement\nfrom first frame (mm, world W)", fontsize=8)
        ax_r.set_ylabel(f"{name} orientation\nx-y-z angles (deg, W)", fontsize=8)
    caption = ("Centre-of-mass displacement r_WB(t) − r_WB(t0) from the first frame, world frame W (the legend gives "
               "each component's first-frame position). Orientation: body-fixed x-y'-z'' Cardan angles "
               "of R_WB = Rx Ry Rz (right-hand rule, positive counter-clockwise), unwrapped over time.")
    return _finish(fig, axes, t, failed, caption)


#: joints' coordinate groups of one unit share a panel while it has at most this many
#: lines (an ankle, a subtalar joint and a toe joint of one coordinate each: one panel)
PANEL_LINES = 3
_COORDINATE_UNITS = {"rad": ("angle", "deg"), "m": ("length", "mm")}


def coordinate_panels(results):
    """The panels of the coordinates' figure: (panels, constant joints). panels: a list
    of (joint names, unit "deg" or "mm", [(coordinate, coordinates.csv column)]), one per
    joint and unit in the model's order (coordinates.csv's without the model: one joint
    "coordinates"), consecutive ones of a unit merged while they have at most
    PANEL_LINES coordinates; a joint and unit whose coordinates are all constant
    (locked, or not moved by the trial) has no panel and is listed in constant joints
    (as "joint (translations)" or "joint (rotations)" when its other unit is drawn).
    ([], []) without coordinates."""
    table = results.coordinates
    if table is None:
        return [], []
    columns = {}
    for col in table.columns:
        name, _, suffix = col.rpartition("_")
        if suffix in _COORDINATE_UNITS:
            columns[name] = col
    model = results.model()
    joints = {c.name: c.joint for c in getattr(model, "coordinates", ())} if model is not None else {}
    groups = {}  # (joint, unit) -> [(coordinate, column)], in the table's (the model's) order
    for name, col in columns.items():
        unit = _COORDINATE_UNITS[col.rpartition("_")[2]][1]
        groups.setdefault((joints.get(name, "coordinates"), unit), []).append((name, col))
    panels, still = [], []
    for (joint, unit), coords in groups.items():
        if all(_is_constant(_col(table, col)) for _, col in coords):
            still.append((joint, unit))
        elif panels and panels[-1][1] == unit and len(panels[-1][2]) + len(coords) <= PANEL_LINES:
            panels[-1] = (panels[-1][0] + [joint], unit, panels[-1][2] + coords)
        else:
            panels.append(([joint], unit, coords))
    drawn = {j for joints, _, _ in panels for j in joints}
    # a joint whose other unit is drawn is named with the kind that does not move
    constant = [f"{joint} ({'rotations' if unit == 'deg' else 'translations'})" if joint in drawn else joint
                for joint, unit in still]
    return panels, list(dict.fromkeys(constant))


def _coordinates(results, t, failed):
    panels, constant = coordinate_panels(results)
    table = results.coordinates
    fig, axes = _figure(len(panels), f"{_name(results)}: joint coordinates")
    for ax, (joints, unit, coords) in zip(axes, panels):
        factor = DISPLAY["angle" if unit == "deg" else "length"][0]
        for name, col in coords:
            values = _col(table, col)
            if _is_constant(values):
                _constant_entry(ax, name, factor * values[np.isfinite(values)][0], unit)
            else:
                ax.plot(t, factor * values, label=name)
        ax.set_ylabel(f"{', '.join(joints)}\n({unit})", fontsize=8)
    caption = ("The model's joint coordinates (coordinates.csv; an OpenSim model's: rotations in degrees, "
               "translations in mm here), one panel per joint in the model's order; joints with few "
               "coordinates share one. A coordinate that does not change is listed as constant, not drawn."
               + (f" Constant throughout, not drawn: {', '.join(constant)}." if constant else ""))
    return _finish(fig, axes, t, failed, caption)


def _measure_kinds(results):
    """Measure kinds (length / angle / 1) from the model when available: (FDK DOF name ->
    kind, constraint row name -> kind); empty dicts without the model."""
    model = results.model()
    dofs, rows = {}, {}
    if model is not None:
        for d in model.fdk_dofs:
            dofs[d.name] = d.measure.units[0] if d.measure.units else "1"
        for c in model.constraints:
            for r, row in enumerate(c.row_names):
                rows[row] = c.measure.units[r] if r < len(c.measure.units) else "1"
    return dofs, rows


def _fdk(results, t, failed):
    dofs = results.fdk_dofs()
    kinds = _measure_kinds(results)[0]
    f = results.forces
    groups = {}
    for d in dofs:
        groups.setdefault(kinds.get(d, "?"), []).append(d)
    fig, axes = _figure(2 * len(groups), f"{_name(results)}: FDK degrees of freedom")
    for g, (kind, names) in enumerate(groups.items()):
        factor, unit = DISPLAY.get(kind, (1.0, "SI: m or rad"))
        force_unit = conjugate_unit(kind) if kind != "?" else "N or N·m"
        for d in names:
            axes[2 * g].plot(t, factor * _col(f, f"fdk.{d}.alpha"), label=d)
            axes[2 * g + 1].plot(t, _col(f, f"fdk.{d}.residual"), label=d)
        axes[2 * g].set_ylabel(f"FDK DOF α\n({unit}, measure frame)", fontsize=8)
        axes[2 * g + 1].set_ylabel(f"residual f^FDK\n({force_unit}, along α)", fontsize=8)
    caption = ("α: value of each FDK DOF's measure (its frame is the measure's: e.g. a plane distance is positive "
               "on the side of the plane normal). f^FDK: residual generalized force the FDK DOF must carry to hold α "
               "(Φ^FDK_qᵀ f^FDK acts on the bodies): positive when the other loads push α to smaller values; a "
               "converged frame has |f^FDK| below the force tolerance.")
    return _finish(fig, axes, t, failed, caption)


def default_measures(names):
    """Measures plotted when none are chosen, from the measure names of a run: the model
    file's own measures first (names without a dot), then the joints' measures
    (``joint.angle``…), at most MAX_DEFAULT_MEASURES."""
    names = list(names)
    return ([n for n in names if "." not in n] + [n for n in names if "." in n])[:MAX_DEFAULT_MEASURES]


_KIND_OF_SUFFIX = {"m": "length", "rad": "angle", "1": "1"}


def measure_series(results, name):
    """Components of measure ``name`` in the run's measures table (measures.csv):
    list of (label, kind, (n_frames,) SI values); [] when the run has no such measure."""
    table = results.measures
    if table is None:
        return []
    out = []
    for col in table.columns:
        base, _, suffix = col.rpartition("_")
        if base == name or (base.startswith(name + "[") and base.endswith("]")):
            out.append((base[len(name):] or name, _KIND_OF_SUFFIX.get(suffix, "1"), _col(table, col)))
    return out


def _measures(results, t, failed, chosen):
    series = {name: measure_series(results, name) for name in chosen}
    unknown = [n for n, s in series.items() if not s]
    if unknown:
        raise ValueError(f"unknown measure(s) {unknown}; the run's measures are {results.measure_names()}")
    model = results.model()
    fig, axes = _figure(len(chosen), f"{_name(results)}: kinematic measures")
    for ax, name in zip(axes, chosen):
        kinds = []
        labels = component_labels(model.measures.get(name) if model is not None else None, series[name])
        for label, (_, kind, values) in zip(labels, series[name]):
            factor, unit = DISPLAY.get(kind, (1.0, ""))
            if _is_constant(values):
                _constant_entry(ax, label, factor * values[np.isfinite(values)][0], unit)
            else:
                ax.plot(t, factor * values, label=label)
            kinds += [kind] if kind not in kinds else []
        units = ", ".join(DISPLAY.get(kd, (1, kd))[1] for kd in kinds)
        frame = _measure_frame(model.measures[name]) if model is not None and name in model.measures else "measure"
        ax.set_ylabel(f"{name}\n({units}, {frame})", fontsize=8)
    caption = ("Named measures of the model (measures.csv) on the solved poses; vector components x, y, z, angles "
               "about x, y', z'' (or the measure's own sequence), [j] component j otherwise; a component that does "
               "not change (a constrained one) is listed as constant, not drawn. Vectors "
               "point from their first to their second point; angles are x-y'-z'' Cardan angles of the second frame "
               "relative to the first.")
    return _finish(fig, axes, t, failed, caption)


def component_labels(measure, series):
    """Legend labels of a measure's components: x/y/z for a 3-vector of lengths, the
    rotation axes of angles (x-y'-z'' Cardan angles, or a JCS/Euler sequence), else
    ``[j]``; ``series``: :func:`measure_series` of the measure."""
    n = len(series)
    if n == 1:
        return [series[0][0]]
    kind = type(measure).__name__ if measure is not None else None
    if kind == "RelativeAngles":
        return ["about x", "about y'", "about z''"]
    sequence = getattr(measure, "sequence", None)
    if kind == "RotationAngles" and isinstance(sequence, str):
        axes = [c for c in sequence.lower() if c in "xyz"]
        if len(axes) == 3:
            return [f"about {a}{'′' * j}" for j, a in enumerate(axes)]
    kinds = {k for _, k, _ in series}
    if n == 3 and (kind in ("PointPosition", "RelativeVector") or (measure is None and kinds == {"length"})):
        return ["x", "y", "z"]
    if n == 3 and measure is None and kinds == {"angle"}:
        return ["about x", "about y'", "about z''"]
    return [label for label, _, _ in series]


def _measure_frame(m):
    frame = getattr(m, "frame", None)
    if type(m).__name__ == "RelativeVector":
        return "world W" if frame is None else "body frame"
    if type(m).__name__ == "PointPosition":
        return "world W"
    if type(m).__name__ == "RelativeAngles":
        return "relative"
    return "scalar"


def _muscles(results, t, failed):
    f = results.forces
    names = results.muscles()
    peak = {n: np.nanmax(np.abs(_col(f, f"{n}.force_N")), initial=0.0) for n in names}
    order = sorted(names, key=lambda n: -peak[n])
    fig, axes = _figure(2, f"{_name(results)}: muscles ({len(names)}; legend: the {min(len(names), MAX_LEGEND)} "
                           f"strongest)")
    for n, (colour, ls) in zip(order, line_styles(len(order))):
        axes[0].plot(t, _col(f, f"{n}.force_N"), lw=1, color=colour, ls=ls, label=n)
        axes[1].plot(t, _col(f, f"{n}.activation"), lw=1, color=colour, ls=ls, label=f"_{n}")  # one legend
    axes[0].set_ylabel("muscle force (N,\ntension along path)", fontsize=8)
    axes[1].set_ylabel("activation f/s (–)", fontsize=8)
    caption = ("Muscle force: tension (≥ 0) along the muscle path, from the recruitment. Activation: force divided by "
               "the current strength s (Hill model at the current length and speed); the passive force is applied "
               "separately (forces.csv, <muscle>.passive_N).")
    return _finish(fig, axes, t, failed, caption)


def _actuators(results, t, failed):
    f = results.forces
    names = results.actuators()
    peak = {n: np.nanmax(np.abs(_col(f, f"{n}.actuator")), initial=0.0) for n in names}
    order = sorted(names, key=lambda n: -peak[n])
    fig, axes = _figure(2, f"{_name(results)}: actuators ({len(names)}; legend: the {min(len(names), MAX_LEGEND)} "
                           "largest)")
    threshold = (results.summary.get("residuals") or {}).get("force_threshold_N")
    if isinstance(threshold, (int, float)) and not isinstance(threshold, bool):  # first: always in the legend
        for sign in (1, -1):
            axes[0].axhline(sign * threshold, color="k", ls="--", lw=0.8,
                            label="±5 % body weight (residual forces)" if sign > 0 else "_")
    for n, (colour, ls) in zip(order, line_styles(len(order))):
        axes[0].plot(t, _col(f, f"{n}.actuator"), lw=1, color=colour, ls=ls, label=n)
        axes[1].plot(t, _col(f, f"{n}.control"), lw=1, color=colour, ls=ls, label=f"_{n}")
    axes[0].set_ylabel("actuator force\n(N or N·m)", fontsize=8)
    axes[1].set_ylabel("control τ/F (–)", fontsize=8)
    caption = ("Actuators (reserve and residual actuators, recruited beside the muscles and weighted by their optimal "
               "force F): coordinate actuators along their coordinate (N·m or N), point actuators along their "
               "direction (N), torque actuators about their axis (N·m). Control: force / F. Residual forces above the "
               "dashed lines make the trial dynamically inconsistent.")
    return _finish(fig, axes, t, failed, caption)


def ligament_bundles(names):
    """{bundle: [strand names]} of ligament strands named <bundle><k> (DM's MCLd1–MCLd3,
    pCAP1–pCAP8), in order of first appearance; a name without a trailing number, or
    whose stem no other strand shares, is a bundle of its own."""
    import re

    stems = [re.sub(r"\d+$", "", n) or n for n in names]
    groups = {}
    for n, stem in zip(names, stems):
        key = stem if stems.count(stem) > 1 else n
        groups.setdefault(key, []).append(n)
    return groups


def _by_peak(f, names, column):
    """``names`` ordered by the peak |value| of their ``column`` (largest first)."""
    peak = {n: np.nanmax(np.abs(_col(f, column.format(n))), initial=0.0) for n in names}
    return sorted(names, key=lambda n: -peak[n])


def _ligaments(results, t, failed):
    f = results.forces
    ligs, springs = results.ligaments(), results.springs()
    bundles = ligament_bundles(ligs)
    by_bundle = len(bundles) < len(ligs)  # strands that share a bundle: their sums too
    title = f"{_name(results)}: ligaments and springs"
    if len(ligs) > MAX_LEGEND:
        title += f" ({len(ligs)} ligament strands; legends: the {MAX_LEGEND} largest)"
    fig, axes = _figure(len([x for x in (ligs, springs) if x]) + (1 + by_bundle if ligs else 0), title)
    i = 0
    if ligs:
        order = _by_peak(f, ligs, "{}.force_N")  # the legend's first entries are the largest
        for n, (colour, ls) in zip(order, line_styles(len(order))):
            axes[0].plot(t, _col(f, f"{n}.force_N"), color=colour, ls=ls, label=n)
            axes[1].plot(t, _col(f, f"{n}.strain"), color=colour, ls=ls, label=n)
        axes[0].set_ylabel("ligament force\n(N, tension)", fontsize=8)
        axes[1].set_ylabel("ligament strain\n(l − l0)/l0 (–)", fontsize=8)
        i = 2
        if by_bundle:
            sums = {b: np.sum([_col(f, f"{n}.force_N") for n in strands], axis=0) for b, strands in bundles.items()}
            peak = {b: np.nanmax(v, initial=0.0) for b, v in sums.items()}
            order = sorted(sums, key=lambda b: -peak[b])
            for b, (colour, ls) in zip(order, line_styles(len(order))):
                k = len(bundles[b])
                axes[2].plot(t, sums[b], color=colour, ls=ls, label=f"{b} ({k} strands)" if k > 1 else b)
            axes[2].set_ylabel("ligament bundle force\n(N, sum of its strands)", fontsize=8)
            i = 3
    if springs:
        for n, (colour, ls) in zip(springs, line_styles(len(springs))):
            axes[i].plot(t, _col(f, f"{n}.force"), color=colour, ls=ls, label=n)
        axes[i].set_ylabel("spring force\n(N or N·m, along measure)", fontsize=8)
    caption = ("Ligament force: tension ≥ 0 along the ligament path (Blankevoort 1991, zero when slack, strain < 0). "
               + ("Bundles: the strands named <bundle><k> (MCLd1, MCLd2, …) summed, a bundle's tension as its "
                  "strands share it. " if ligs and by_bundle else "")
               + "Spring force f = −k (m − m_rest): generalized force along its measure, N for a length, N·m for an "
               "angle, positive when it pushes the measure to larger values.")
    return _finish(fig, axes, t, failed, caption)


def contact_body_pose(results, name):
    """(body name, r_WB (n_frames, 3) m, R_WB (n_frames, 3, 3)): the pose of the body
    carrying contact ``name``'s 'vertices' surface (the body its force acts on; frame B
    with its origin at the centre of mass, docs/outputs.md), from kinematics.csv (a
    fixed body: its pose in the model); NaN where a frame has none. None without the
    model, the contact in it, or the body's poses in kinematics.csv (a model other than
    the run's)."""
    from ..numerics.spatial import rotation_matrix

    model = results.model()
    element = next((c for c in getattr(model, "contacts", ()) if c.name == name), None) if model else None
    if element is None:
        return None
    body = model.bodies[element.body_a].name
    k, n = results.kinematics, len(results.time)
    if f"{body}.x_m" in k.columns:
        r_WB = np.column_stack([_col(k, f"{body}.{c}_m") for c in "xyz"])
        R_WB = np.full((n, 3, 3), np.nan)
        for i, q in enumerate(np.column_stack([_col(k, f"{body}.e{j}") for j in range(4)])):
            if np.all(np.isfinite(q)):
                R_WB[i] = rotation_matrix(q / np.linalg.norm(q))
        return body, r_WB, R_WB
    if not model.bodies[element.body_a].fixed:  # a model other than the run's (--model)
        return None
    state = model.initial_state()  # a fixed body (not in kinematics.csv): where the model puts it
    return body, np.broadcast_to(state.p_WB[element.body_a], (n, 3)), np.broadcast_to(state.R_WB[element.body_a],
                                                                                        (n, 3, 3))


def contact_regions(results, name):
    """[(region, forces.csv column)] of contact ``name``: its ``<contact>.<region>_N``
    columns, the force magnitude (N) on each region's vertices (a knee's medial and
    lateral compartments; docs/contact.md, "Regions"); [] without regions."""
    prefix = f"{name}."
    return [(c[len(prefix):-2], c) for c in results.forces.columns
            if c.startswith(prefix) and c.endswith("_N") and c[len(prefix):-2] not in ("Fx", "Fy", "Fz")]


def body_weight(results):
    """The body weight (N) summary.json records for a run with residual actuators
    (``residuals.body_weight_N``, a whole-body model), else None."""
    value = (results.summary.get("residuals") or {}).get("body_weight_N")
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value) and value > 0
    return float(value) if ok else None


def _contact(results, t, failed):
    f = results.forces
    names = results.contacts()
    regions = {n: contact_regions(results, n) for n in names}
    poses = {n: contact_body_pose(results, n) for n in names}
    # the body frame when the model gives every contact's body, else the world (no model)
    in_body = True if names and all(v is not None for v in poses.values()) else None
    fig, axes = _figure(3 + any(regions.values()), f"{_name(results)}: contact")
    for n in names:
        F = np.column_stack([_col(f, f"{n}.F{c}_N") for c in "xyz"])
        # along the axes of the body the force acts on (a knee's compressive and shear parts)
        F_shown = np.einsum("nji,nj->ni", poses[n][2], F) if in_body is not None else F
        where = f" ({poses[n][0]})" if in_body is not None else ""
        for j, c in enumerate("xyz"):
            axes[0].plot(t, F_shown[:, j], lw=1, label=f"{n} F{c}{where}")
        axes[0].plot(t, np.linalg.norm(F, axis=1), "k" if len(names) == 1 else "-", lw=1.6, label=f"{n} |F|")
        if in_body is not None:  # where on the body the contact presses: its path over the surface
            body, r_WB, R_WB = poses[n]
            p_W = np.column_stack([_col(f, f"{n}.cop_{c}_m") for c in "xyz"])
            p_B = np.einsum("nji,nj->ni", R_WB, p_W - r_WB)  # R_WBᵀ (p_W − r_WB)
            for c, values in zip("xyz", 1e3 * p_B.T):
                axes[1].plot(t, values, lw=1, label=f"{n} {c} ({body})")
        else:
            for c in "xyz":  # from the first frame in contact: millimetres stay visible in a lab frame
                cop = 1e3 * _col(f, f"{n}.cop_{c}_m")
                finite = np.flatnonzero(np.isfinite(cop))
                if finite.size:
                    axes[1].plot(t, cop - cop[finite[0]], lw=1, label=f"{n} {c} (from {cop[finite[0]]:.1f} mm)")
        axes[2].plot(t, 1e6 * _col(f, f"{n}.area_m2"), lw=1, label=n)
    axes[0].set_ylabel("contact force\n(N, body frame B)" if in_body is not None else "contact force\n(N, world W)",
                       fontsize=8)
    axes[1].set_ylabel("centre of pressure\n(mm, body frame B)" if in_body is not None
                       else "centre of pressure, from\nfirst contact (mm, world W)", fontsize=8)
    axes[2].set_ylabel("contact area (mm²)", fontsize=8)
    caption = ("Contact force: resultant elastic-foundation force on the body carrying the contact's 'vertices' "
               "surface, " + ("components along that body's axes B (the legend names it; forces.csv keeps the world's)"
                              if in_body is not None else "world components")
               + " (the opposite body receives −F). Centre of pressure: pressure-weighted "
               "mean of the contact points, "
               + ("in the frame B of that body (origin at its centre of mass; the legend names it): the path of the "
                  "contact over the body, undefined (gap) without contact." if in_body is not None else
                  "world frame, as displacement from the first frame in contact (the legend gives where it starts), "
                  "undefined (gap) without contact."))
    if any(regions.values()):
        weight = body_weight(results)
        ax = axes[3]
        for n, (colour, _) in zip([n for n in names if regions[n]], line_styles(len(names))):
            total = np.linalg.norm(np.column_stack([_col(f, f"{n}.F{c}_N") for c in "xyz"]), axis=1)
            for (label, values), ls in zip([("|F|", total)] + [(r, _col(f, col)) for r, col in regions[n]],
                                           ("-", "--", ":", "-.") * 4):
                peak = f" (peak {np.nanmax(values, initial=0.0) / weight:.2f} BW)" if weight else ""
                ax.plot(t, values, color=colour, ls=ls, lw=1.6 if label == "|F|" else 1, label=f"{n} {label}{peak}")
        ax.set_ylabel("contact force by region\n(N" + (f"; 1 BW = {weight:.0f} N)" if weight else ")"), fontsize=8)
        caption += (" By region: the magnitude of the force on each region's vertices (e.g. a knee's medial and "
                    "lateral compartments), beside the whole contact's |F|; regions need not cover the contact."
                    + (f" BW: the body weight, {weight:.1f} N." if weight else ""))
    return _finish(fig, axes, t, failed, caption)


def _reactions(results, t, failed):
    f = results.forces
    names = results.reactions()
    kinds = _measure_kinds(results)[1]
    groups = {}
    for n in names:
        groups.setdefault(conjugate_unit(kinds[n]) if n in kinds else "N or N·m", []).append(n)
    title = f"{_name(results)}: joint and constraint reactions"
    if any(len(rows) > MAX_LEGEND for rows in groups.values()):
        title += f" ({len(names)} rows; legends: the {MAX_LEGEND} largest)"
    fig, axes = _figure(len(groups), title)
    for ax, (unit, rows) in zip(axes, groups.items()):
        rows = _by_peak(f, rows, "{}.reaction")  # the legend's first entries are the largest
        for n, (colour, ls) in zip(rows, line_styles(len(rows))):
            ax.plot(t, _col(f, f"{n}.reaction"), lw=1, color=colour, ls=ls, label=n)
        what = "reaction force" if unit == "N" else "reaction moment" if unit == "N·m" else "reaction"
        ax.set_ylabel(f"{what}\n({unit}, constraint frame)", fontsize=8)
    caption = ("Reaction λ of each constraint row: the load Φ_qᵀλ acts on the bodies. For a joint's x/y/z rows "
               "(child origin − parent origin, in the parent joint frame) λ is the force on the child body along "
               "that axis of the parent frame, −λ on the parent; rotational rows are moments (N·m).")
    return _finish(fig, axes, t, failed, caption)


def _body_weight(results):
    """The body weight (N) summary.json's joint loads give, or None."""
    weight = (results.summary.get("joint_loads") or {}).get("body_weight_N")
    return float(weight) if isinstance(weight, (int, float)) and weight > 0 else None


def _joint_loads(results, t, failed):
    f = results.joint_loads
    joints = joint_load_bases(f.columns)[0]
    weight = _body_weight(results)
    title = f"{_name(results)}: joint loads"
    if len(joints) > MAX_LEGEND:
        title += f" ({len(joints)} joints; legends: the {MAX_LEGEND} largest)"
    fig, axes = _figure(2, title)
    for ax, kind in zip(axes, "fm"):
        size = {j: np.linalg.norm(np.column_stack([_col(f, f"{j}_{kind}{c}") for c in "xyz"]), axis=1)
                for j in joints}
        order = sorted(joints, key=lambda j: -np.nanmax(size[j], initial=0.0))[:MAX_LEGEND]
        rest = [j for j in joints if j not in order]
        for j in rest:  # drawn, grey and unnamed: small loads
            ax.plot(t, size[j] / (weight if kind == "f" and weight else 1.0), lw=0.6, color="0.7")
        for j, (colour, ls) in zip(order, line_styles(len(order))):
            values = size[j] / (weight if kind == "f" and weight else 1.0)
            peak = np.nanmax(values, initial=0.0)
            label = j.rsplit("_on_", 1)[0] + f" (peak {peak:.2f}{' BW' if kind == 'f' and weight else ''})"
            ax.plot(t, values, lw=1, color=colour, ls=ls, label=label)
    axes[0].set_ylabel("joint force |F|\n" + (f"(BW; 1 BW = {weight:.0f} N)" if weight else "(N)"), fontsize=8)
    axes[1].set_ylabel("joint moment |M|\n(N·m, about the joint centre)", fontsize=8)
    caption = ("The load each joint transmits to its child body, as OpenSim's JointReaction reports it: its "
               "constraint reactions, the drivers' generalised forces on its coordinates, the coordinate actuators "
               "on them, and what OpenSim applies as generalised forces on them (moving path points, coordinate "
               "couplers); muscles, ligaments and contacts otherwise act on the bodies, not through the joint. "
               "Moments about the origin of the joint's child frame. Components in joint_loads.csv (ground frame).")
    return _finish(fig, axes, t, failed, caption)


def _joint_reaction(results, t, failed):
    """The force components of the model file's ``joint_reaction`` reports, one panel per
    report (at most MAX_LEGEND), in body weights in the report's frame."""
    f = results.joint_loads
    reports = joint_load_bases(f.columns)[1]
    weight = _body_weight(results)
    shown = reports[:MAX_LEGEND]
    title = f"{_name(results)}: joint reactions as asked (joint_reaction)"
    if len(reports) > len(shown):
        title += f" (the first {len(shown)} of {len(reports)})"
    fig, axes = _figure(len(shown), title)
    scale = weight or 1.0
    for ax, base in zip(axes, shown):
        joint, rest = base.rsplit("_on_", 1)
        body, frame = rest.rsplit("_in_", 1)
        for c, (colour, ls) in zip("xyz", line_styles(3)):
            values = _col(f, f"{base}_f{c}") / scale
            ax.plot(t, values, lw=1, color=colour, ls=ls,
                    label=f"F{c} (range {np.nanmin(values, initial=0.0):.2f} to {np.nanmax(values, initial=0.0):.2f})")
        ax.set_ylabel(f"{joint} on {body}\nin {frame} " + (f"(BW; 1 BW = {weight:.0f} N)" if weight else "(N)"),
                      fontsize=8)
    caption = ("Each requested report of the joint_reaction section (OpenSim's JointReaction options): the force "
               "the joint applies to the named body, its components along the axes of the named frame (for an "
               "OpenSim model, the OpenSim body's axes). Moments and points in joint_loads.csv and .sto.")
    return _finish(fig, axes, t, failed, caption)


#: at most this many coordinates in the moment arms' figure (those most muscles span)
MOMENT_ARM_PANELS = 8


def moment_arm_panels(results):
    """[(coordinate, coordinates.csv column, unit "deg" or "mm", [muscles])] of the moment
    arms' figure: the coordinates the most muscles span (moment_arms.csv), at most
    MOMENT_ARM_PANELS, each with its muscles in the table's order; and the number of
    coordinates in the table."""
    table, coords = results.moment_arms, results.coordinates
    if table is None or coords is None:
        return [], 0
    spans = {}
    for col in table.columns:
        muscle, _, coordinate = col.partition(".")
        spans.setdefault(coordinate, []).append(muscle)
    found = []
    for coordinate, muscles in spans.items():
        for suffix, (_, unit) in _COORDINATE_UNITS.items():
            if f"{coordinate}_{suffix}" in coords.columns:
                found.append((coordinate, f"{coordinate}_{suffix}", unit, muscles))
    order = sorted(found, key=lambda p: -len(p[3]))[:MOMENT_ARM_PANELS]
    return [p for p in found if p in order], len(spans)


def _moment_arms(results, t, failed):
    """Each muscle's moment arm (mm) against the coordinate's value (deg or mm) over the
    trial, one panel per coordinate (:func:`moment_arm_panels`): the classic moment-arm
    curves, traced as the trial moves the joint."""
    from matplotlib.figure import Figure

    panels, total = moment_arm_panels(results)
    title = f"{_name(results)}: muscle moment arms"
    if total > len(panels):
        title += f" (the {len(panels)} coordinates most muscles span, of {total})"
    height = 0.9 + 2.6 * len(panels)
    fig = Figure(figsize=(11.0, height))
    axes = list(fig.subplots(len(panels), 1, squeeze=False)[:, 0])
    fig.suptitle(title, fontsize=11, y=1.0 - TITLE_TOP_IN / height)
    table, coords = results.moment_arms, results.coordinates
    for ax, (coordinate, column, unit, muscles) in zip(axes, panels):
        x = _col(coords, column) * (np.degrees(1.0) if unit == "deg" else 1e3)
        order = sorted(muscles, key=lambda m: -np.nanmax(np.abs(_col(table, f"{m}.{coordinate}")), initial=0.0))
        shown = order[:MAX_LEGEND]
        for m in order[MAX_LEGEND:]:
            ax.plot(x, 1e3 * _col(table, f"{m}.{coordinate}"), lw=0.6, color="0.7")
        for m, (colour, ls) in zip(shown, line_styles(len(shown))):
            ax.plot(x, 1e3 * _col(table, f"{m}.{coordinate}"), lw=1, color=colour, ls=ls, label=m)
        ax.axhline(0.0, color="0.5", lw=0.5)
        ax.set_xlabel(f"{coordinate} ({unit})", fontsize=8)
        ax.set_ylabel(f"moment arm\n(mm{'' if unit == 'deg' else ' per m'})", fontsize=8)
    caption = ("Moment arm r = -dl/dq of each muscle about each coordinate it spans (moment_arms.csv, OpenSim's "
               "computeMomentArm), the other coordinates held, couplers followed; against the coordinate's value "
               "over the trial. Positive: the muscle's tension turns the coordinate positive. Grey: beyond the "
               f"{MAX_LEGEND} largest.")
    return _finish(fig, axes, np.zeros(0), np.zeros(0, bool), caption)


def _convergence(results, t, failed):
    """Per-frame iterations (integer ticks) and residuals of each stage, one panel each;
    a panel whose values are all zero (a stage without iterations) is not drawn and
    the caption says so."""
    from matplotlib.ticker import MaxNLocator

    k, f = results.kinematics, results.forces
    fdk = results.fdk
    viol = np.abs(_col(k, "constraint_violation"))
    panels = [("kinematics\niterations (–)", [("kinematics", _col(k, "iterations"))], "iterations"),
              ("constraint\nviolation (m or rad)", [("max |Φ|", viol)], "log")]
    if f is not None and "recruitment_iterations" in f.columns:
        panels.append(("recruitment\niterations (–)", [("recruitment", _col(f, "recruitment_iterations"))],
                       "iterations"))
    if fdk is not None:
        panels.append(("FDK iterations,\nevaluations (–)", [("FDK Newton iterations", _col(fdk, "fdk_iterations")),
                                                             ("FDK residual evaluations",
                                                              _col(fdk, "fdk_evaluations"))], "iterations"))
        columns = [c for c in fdk.columns if c.startswith("fdk.") and ".residual" in c]
        if columns:
            res = np.nanmax(np.abs(np.column_stack([_col(fdk, c) for c in columns])), axis=1)
            panels.append(("max |f^FDK|\n(N or N·m)", [("max |f^FDK|", res)], "log"))
    shown, dropped = [], []
    for label, series, kind in panels:
        values = np.concatenate([v for _, v in series])
        if not np.any(np.nan_to_num(values) != 0):
            dropped.append(label.split("\n")[0])
        else:
            shown.append((label, series, kind))
    fig, axes = _figure(len(shown), f"{_name(results)}: per-frame convergence")
    for ax, (label, series, kind) in zip(axes, shown):
        for name, values in series:
            if kind == "log":
                ax.semilogy(t, np.where(values > 0, values, np.nan), ".-", lw=0.8, label=name)
            else:
                ax.plot(t, values, ".-", lw=0.8, label=name)
        if kind == "iterations":
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
            counts = np.concatenate([np.asarray(v, dtype=float) for _, v in series])
            lo, hi = np.nanmin(counts), np.nanmax(counts)
            if hi - lo < 2:  # a (nearly) constant count: a range with integer ticks around it
                ax.set_ylim(np.floor(lo) - 1, np.ceil(hi) + 1)
        ax.set_ylabel(label, fontsize=8)
    bad = np.flatnonzero(failed)
    if bad.size and shown and shown[0][0].startswith("kinematics"):
        axes[0].plot(t[bad], _col(k, "iterations")[bad], "rx", ms=7, label="failed frame")
    # frames that failed and were solved again backward from a later frame (docs/fdk.md,
    # "Sweeping back"): their counts hold both solves
    backward = np.flatnonzero(_col(fdk, "fdk_backward") > 0) if fdk is not None and "fdk_backward" in fdk else []
    row = next((i for i, (label, _, _) in enumerate(shown) if label.startswith("FDK iterations")), None)
    if len(backward) and row is not None:
        axes[row].plot(t[backward], _col(fdk, "fdk_evaluations")[backward], "v", color="tab:purple", ms=7,
                       label="solved backward")
    caption = ("Iterations per frame of each stage; constraint violation max |Φ| after the position solve; FDK: Newton "
               "iterations, residual evaluations and the final max |f^FDK|."
               + (" ▽: a frame that failed and was solved again backward from the next converged frame (its counts "
                  "are both solves')." if len(backward) and row is not None else "")
               + (f" Zero on every frame, not drawn: {', '.join(dropped)}." if dropped else ""))
    return _finish(fig, axes, t, failed, caption)


def _name(results):
    return results.summary.get("kinematics", {}).get("model") or "run"


# ---------------------------------------------------------------------------- API
def figure_plan(results, measures=None):
    """The figures of a run, not yet drawn: a list of (name, build, weight) in the order
    of the module docstring, one per topic the run has data for. ``build()`` draws the
    figure (a matplotlib Figure); ``weight`` is its expected drawing cost in axes (the
    body poses' figure has two per body, the coordinates' one per panel, the others a
    few), for sharing the figures
    between processes (:mod:`.parallel`).

    measures: names of the run's measures to plot (measures.csv; default:
    :func:`default_measures`; an empty list plots none)."""
    t = results.time
    failed = _failed(results)
    panels = coordinate_panels(results)[0]
    if panels:  # a model with joint coordinates: those, not the bodies' poses
        plan = [("kinematics", lambda: _coordinates(results, t, failed), len(panels))]
    else:
        plan = [("kinematics", lambda: _kinematics(results, t, failed), 2 * len(results.bodies()))]
    if results.fdk_dofs():
        plan.append(("fdk_dofs", lambda: _fdk(results, t, failed), FIGURE_WEIGHT))
    if measures is None:
        measures = default_measures(results.measure_names())
    if measures:
        plan.append(("measures", lambda: _measures(results, t, failed, list(measures)), FIGURE_WEIGHT))
    for name, has, draw in (("muscles", results.muscles, _muscles), ("actuators", results.actuators, _actuators),
                            ("ligaments", lambda: results.ligaments() or results.springs(), _ligaments),
                            ("contact", results.contacts, _contact), ("reactions", results.reactions, _reactions)):
        if has():
            plan.append((name, lambda draw=draw: draw(results, t, failed), FIGURE_WEIGHT))
    if getattr(results, "joint_loads", None) is not None and len(results.joint_loads.columns):
        plan.append(("joint_loads", lambda: _joint_loads(results, t, failed), FIGURE_WEIGHT))
        reports = joint_load_bases(results.joint_loads.columns)[1]
        if reports:
            plan.append(("joint_reaction", lambda: _joint_reaction(results, t, failed),
                         min(len(reports), MAX_LEGEND)))
    if moment_arm_panels(results)[0]:
        plan.append(("moment_arms", lambda: _moment_arms(results, t, failed), len(moment_arm_panels(results)[0])))
    plan.append(("convergence", lambda: _convergence(results, t, failed), FIGURE_WEIGHT))
    return plan


def iter_figures(results, measures=None):
    """The figures of a run, built one at a time: yields (name, matplotlib Figure), one
    per topic the run has data for (see the module docstring and :func:`figure_plan`).
    Writing them as they come keeps one figure of a long run in memory, not all of them."""
    for name, build, _ in figure_plan(results, measures):
        yield name, build()


def make_figures(results, measures=None) -> dict:
    """Figures of a run (a :class:`~openfdk.results.run.RunResults`): dict name ->
    matplotlib Figure (:func:`iter_figures`)."""
    return dict(iter_figures(results, measures))


def save_figures(figures, directory, dpi=110) -> list[Path]:
    """Write each figure as ``<name>.png`` into ``directory`` (created); figures: a dict
    name -> Figure or an iterable of (name, Figure) pairs (:func:`iter_figures`)."""
    import io

    from ..io.outdir import refuse_link, write_new_file

    d = Path(directory)
    refuse_link(d)  # a planted link is refused, never followed
    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fig in figures.items() if isinstance(figures, dict) else figures:
        paths.append(d / f"{name}.png")
        buf = io.BytesIO()
        fig.savefig(buf, dpi=dpi, format="png")
        write_new_file(paths[-1], buf.getvalue())
    return paths


__all__ += ["default_measures", "measure_series", "measure_unit", "coordinate_panels", "contact_regions", "body_weight", "contact_body_pose", "ligament_bundles"]
