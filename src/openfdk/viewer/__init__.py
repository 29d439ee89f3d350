"""``openfdk view``: one self-contained, offline HTML file that plays a run in 3D.

    from openfdk.viewer import write_view
    write_view("results/run1")            # -> results/run1/view.html

The page (three.js, inlined) shows the body frames, contact surfaces and visual meshes,
measured and model markers with residual lines, muscles/ligaments/springs coloured by
force, the contact pressure map and force vector, and the FDK DOFs and residuals in a
side panel, with play/pause, a time slider, speed control, orbit/pan/zoom and
anatomical preset views. See docs/viewer.md.
"""

from __future__ import annotations

from pathlib import Path

from .frames import build_frames
from .page import render_page
from .results import ViewError, read_results, resolve_input
from .scene import MAX_MESH_VERTICES, build_scene

__all__ = ["write_view", "view_data", "ViewError"]


#: the smallest ``max_vertices`` (a displayed mesh keeps at least one triangle)
MIN_MESH_VERTICES = 3


def view_data(result_dir, model=None, max_vertices=MAX_MESH_VERTICES, start=None, end=None):
    """(data dict {meta, scene, frames}, title) of a result folder. ``model``: a model
    file path (default: the one named in summary.json) or a loaded Model; ``start``,
    ``end`` (s): only the frames within (a cycle of a long trial; None: the run's first
    or last)."""
    if isinstance(max_vertices, bool) or not isinstance(max_vertices, int) or max_vertices < MIN_MESH_VERTICES:
        raise ValueError(f"max_vertices must be a whole number >= {MIN_MESH_VERTICES}, got {max_vertices!r}")
    from ..io.modelfile import load_model_for_results

    results = read_results(result_dir)
    if start is not None or end is not None:
        results = results.window(start, end)
    if model is None or not hasattr(model, "bodies"):
        path = resolve_input(results, "model", model)
        if path is None:
            raise ViewError(f"{results.directory / 'summary.json'}: names no model file (input.model); "
                            f"give it with --model")
        model_obj, label = load_model_for_results(path, results.summary), str(path)
    else:
        model_obj, label = model, model.name
    scene = build_scene(model_obj, max_vertices)
    frames = build_frames(model_obj, scene, results)
    info = results.summary.get("input", {}) if isinstance(results.summary, dict) else {}
    t = results.time
    lines = [f"model: {label}"]
    if info.get("trial"):
        lines.append(f"trial: {info['trial']}")
    lines.append(f"{results.n_frames} frames, t = {t[0]:.3f} … {t[-1]:.3f} s" if len(t) else "no frames")
    fdk = results.summary.get("fdk") if isinstance(results.summary, dict) else None
    if isinstance(fdk, dict) and "converged_frames" in fdk:
        lines.append(f"FDK: {fdk['converged_frames']}/{fdk.get('frames', results.n_frames)} frames converged")
    title = f"{model_obj.name} — {Path(results.directory).resolve().name}"
    data = {"meta": {"title": title, "lines": lines}, "scene": scene.data, "frames": frames}
    return data, title


def write_view(result_dir, out=None, model=None, max_vertices=MAX_MESH_VERTICES, start=None, end=None):
    """Write the viewer of ``result_dir`` (its frames within ``start``–``end`` s, when
    given) to ``out`` (default RESULT_DIR/view.html); returns its Path. Raises ViewError
    naming the file/entry on bad input."""
    data, title = view_data(result_dir, model, max_vertices, start, end)
    out = Path(out) if out is not None else Path(result_dir) / "view.html"
    from ..io.outdir import refuse_link, write_new_file

    out.parent.mkdir(parents=True, exist_ok=True)
    refuse_link(out)
    tmp = out.with_name(f".{out.name}.tmp")
    write_new_file(tmp, render_page(data, title).encode("utf-8"))  # a planted link is refused, not followed
    tmp.replace(out)
    return out
