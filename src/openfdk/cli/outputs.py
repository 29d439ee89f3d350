"""Command-line pieces for a run's outputs: figures, OpenSim files.

    openfdk plot RESULT_DIR [--out DIR] [--measures NAME ...]   PNG figures of a run
    openfdk export-opensim RESULT_DIR --out DIR [--model M]     .osim + .mot (+ meshes)
    openfdk run ... [--no-plots]                                 STO twins and figures after a run

Kept apart from :mod:`openfdk.cli` so that the main parser only registers them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def _say(args, text):
    """An informational line on stdout, unless --quiet."""
    if not getattr(args, "quiet", False):
        print(text)


def refuse_empty_out(args):
    """``--out ''`` is refused (it would write into the current folder)."""
    if args.out is not None and not str(args.out).strip():
        raise ValueError("the output is empty (--out ''); give a folder or file name")


def _cmd_plot(args):
    from ..plots.parallel import write_figures
    from ..results.run import read_results

    refuse_empty_out(args)

    results = read_results(args.result_dir)
    if args.model:
        from ..io.modelfile import load_model_for_results

        results._model = load_model_for_results(args.model, results.summary)
    out = Path(args.out) if args.out else Path(args.result_dir) / "plots"
    paths = write_figures(results, out, measures=args.measures)
    _say(args, f"plot: {len(paths)} figures -> {out}/ ({', '.join(p.name for p in paths)})")
    return 0


def _cmd_export_opensim(args):
    from ..io.osim import export_opensim

    refuse_empty_out(args)

    model = None
    if args.model:
        from ..io.modelfile import load_model_for_results

        model = load_model_for_results(args.model)
    res = export_opensim(args.result_dir, args.out, model=model)
    from ..io.osim import note_lines

    for line in note_lines(res["notes"]) if not getattr(args, "quiet", False) else ():
        print(f"export-opensim: {line}", file=sys.stderr)  # what OpenSim cannot hold, one line per kind
    _say(args, f"export-opensim: {res['osim']} and {res['mot']} ({res['frames']} frames"
          + (f", {len(res['skipped_frames'])} failed frames left out" if res["skipped_frames"] else "")
          + (f", {len(res['geometry'])} meshes in {Path(args.out) / 'Geometry'}" if res["geometry"] else "") + ")")
    return 0


def add_output_parsers(sub):
    """Register ``plot`` and ``export-opensim`` on the main parser's subparsers."""
    from .argtypes import _display_arguments

    p = sub.add_parser("plot", help="PNG figures of a run (kinematics, FDK, muscles, contact, reactions, convergence)",
                       description="Draw the PNG figures of a result folder of openfdk run / kinematics (the same "
                                   "figures `openfdk run` writes to RESULT_DIR/plots; docs/outputs.md#figures).")
    p.add_argument("result_dir", help="output folder of openfdk run / kinematics")
    p.add_argument("--out", default=None, help="figure folder (default RESULT_DIR/plots)")
    p.add_argument("--measures", nargs="*", default=None,
                   help="model measures to plot (default: the model's first named measures; none: --measures)")
    p.add_argument("--model", default=None, help="model file (default: the one recorded in summary.json)")
    _display_arguments(p, progress=False)
    p.set_defaults(func=_cmd_plot)

    e = sub.add_parser("export-opensim", help="an OpenSim .osim model (joints, coordinates, markers, muscles, "
                                              "ligaments, meshes) and a .mot motion of a run",
                       description="Write a run as an OpenSim model (.osim: bodies, joints and coordinates, "
                                   "constraints, markers, muscles and ligaments, meshes) and a .mot of its joint "
                                   "coordinates at the converged frames; what OpenSim cannot hold is named on "
                                   "stderr, one line per kind (docs/opensim.md).")
    e.add_argument("result_dir", help="output folder of openfdk run / kinematics")
    e.add_argument("--out", required=True, help="folder for the .osim, .mot and Geometry/")
    e.add_argument("--model", default=None, help="model file (default: the one recorded in summary.json)")
    _display_arguments(e, progress=False)
    e.set_defaults(func=_cmd_export_opensim)


def add_run_output_arguments(p):
    """``--no-plots`` for ``openfdk run``."""
    p.add_argument("--no-plots", action="store_true", help="do not write the figures (RESULT_DIR/plots/*.png)")


def record_model_file(out_dir, model_path):
    """Add the model file's absolute path to summary.json (``input.model_file``), so
    that ``plot`` and ``export-opensim`` find the model from any folder."""
    path = Path(out_dir) / "summary.json"
    if not path.is_file() or not model_path:
        return
    from ..io.results import write_json

    summary = json.loads(path.read_text())
    summary.setdefault("input", {})["model_file"] = str(Path(model_path).resolve())
    write_json(path, summary)


def after_run(args, plots=True, model=None, side=None):
    """After ``openfdk run``/``kinematics`` wrote its CSV files: record the model file,
    write the ``.sto`` twins and (unless ``--no-plots``) the figures (``model``: the
    run's Model, already loaded). A figure that cannot be drawn is reported on stderr;
    the run's results stay. ``side``: a :class:`~openfdk.plots.parallel.SideJob`
    (``openfdk run``'s contact-rim check) computed in a figure worker when there are
    workers, else here; it is finished (reported) exactly once, also without figures or
    when they fail, and an error of its own is raised as its own, after the figures."""
    from ..io.storage import csv_to_sto

    out = Path(args.out)
    record_model_file(out, args.model)
    written = [p for p in (csv_to_sto(out / name) for name in ("kinematics.csv", "forces.csv", "measures.csv")
                           if (out / name).is_file()) if p is not None]
    quiet = getattr(args, "quiet", False)
    if written and not quiet:
        print(f"  OpenSim storage: {', '.join(str(p) for p in written)}")
    paths = None
    if plots and not getattr(args, "no_plots", False):
        try:
            from ..plots.parallel import write_plots

            paths = write_plots(out, model=model, side=side)
        except Exception as exc:  # the analysis results are written; report and go on
            print(f"openfdk: warning: figures not written: {type(exc).__name__}: {exc}", file=sys.stderr)
    if side is not None:
        side.finish()
    if paths is None:
        return
    if not quiet:
        print(f"  figures: {len(paths)} PNG files -> {out / 'plots'}/")
