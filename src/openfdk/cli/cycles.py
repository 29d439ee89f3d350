"""``openfdk cycles RUN_DIR --foot BODY``: a run's gait cycles, found from its measured
loads, and its contact forces and FDK DOFs over them, as mean ± SD across the cycles
(:mod:`openfdk.analysis.gait_cycles`; docs/outputs.md#gait-cycles).

Writes cycles.csv, cycles_list.csv and cycles.png (unless ``--no-plot``) to ``--out``
(default RUN_DIR/cycles) and prints the cycles. Kept apart from
:mod:`openfdk.cli.commands`, which only registers it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import argtypes
from .argtypes import _display_arguments


def _cmd_cycles(args):
    from ..analysis.gait_cycles import CycleError, gait_cycles, write_cycles
    from ..results.run import read_results

    if args.out is not None and not str(args.out).strip():
        raise ValueError("the output is empty (--out ''); give a folder name")
    try:
        results = read_results(args.run_dir)
    except FileNotFoundError as exc:
        raise CycleError(str(exc)) from None
    if results.forces is None:
        raise CycleError(f"{args.run_dir}: no forces.csv; cycles need a run with forces (openfdk run)")
    cycles = gait_cycles(results, args.foot, args.threshold, args.min_off, args.min_on)
    from ..plots.run import body_weight

    weight = body_weight(results)
    figure = None
    if not args.no_plot:
        from ..plots.gait_cycles import cycles_figure

        figure = cycles_figure(cycles, weight, title=Path(args.run_dir).name)
    out = Path(args.out) if args.out else Path(args.run_dir) / "cycles"
    paths = write_cycles(cycles, out, figure)
    if not getattr(args, "quiet", False):
        durations = cycles.strikes[1:] - cycles.strikes[:-1]
        print(f"cycles: {results.directory}, foot {args.foot}: {cycles.n_cycles} cycle(s) from "
              f"{cycles.strikes[0]:.4f} to {cycles.strikes[-1]:.4f} s, {durations.min():.3f}–{durations.max():.3f} s "
              f"long; {int(cycles.failed.sum())} failed frame(s) within them")
        stance = cycles.stance_percent
        if np.any(np.isfinite(stance)):
            print(f"  stance: {np.nanmean(stance):.1f} % of the cycle (mean; toe-off where the load falls through "
                  f"{cycles.threshold_N:g} N)")
        for name in cycles.per_cycle:
            mean = cycles.mean(name)
            if name.endswith(".|F|_N") and np.any(np.isfinite(mean)):
                i = int(np.nanargmax(mean))
                scale, unit = (1.0 / weight, "BW") if weight else (1.0, "N")
                sd = cycles.sd(name)[i]
                spread = f" (SD {sd * scale:.2f} {unit})" if np.isfinite(sd) else ""  # one cycle: none
                print(f"  {name[:-len('.|F|_N')]}: mean peak {mean[i] * scale:.2f} {unit} at {i} %{spread}")
        print(f"  -> {', '.join(str(p) for p in paths)}")
    return 0


def add_cycles_parser(sub):
    """Register ``cycles`` on the main parser's subparsers."""
    c = sub.add_parser(
        "cycles", help="a run's gait cycles from its measured loads: contact forces and FDK DOFs as mean ± SD "
                       "over the cycles (table and figure)",
        description="Find a run's gait cycles from the measured loads on a foot (heel strike: its vertical load "
                    "rising through --threshold) and write its contact forces and FDK DOFs over %% of the cycle: "
                    "the mean, the SD and the number of cycles at each %% (cycles.csv), the cycles' heel strikes "
                    "(cycles_list.csv) and a figure (cycles.png); docs/outputs.md.")
    c.add_argument("run_dir", help="output folder of openfdk run (with measured loads: --external-loads)")
    c.add_argument("--foot", required=True, metavar="BODY", help="the body the foot's measured loads act on, "
                                                                  "e.g. calcn_r")
    c.add_argument("--threshold", type=argtypes.finite, default=20.0, metavar="N",
                   help="vertical load (N) whose rise through it is a heel strike (default 20)")
    c.add_argument("--min-off", type=argtypes.finite, default=0.2, metavar="S",
                   help="least time (s) below the threshold before a heel strike (default 0.2)")
    c.add_argument("--min-on", type=argtypes.finite, default=0.2, metavar="S",
                   help="least time (s) at or above the threshold after it (default 0.2)")
    c.add_argument("--out", default=None, help="folder of cycles.csv/cycles_list.csv/cycles.png "
                                               "(default RUN_DIR/cycles)")
    c.add_argument("--no-plot", action="store_true", help="do not draw cycles.png")
    _display_arguments(c, progress=False)
    c.set_defaults(func=_cmd_cycles)
