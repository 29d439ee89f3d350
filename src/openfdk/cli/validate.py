"""``openfdk validate-kinematics RUN_DIR REFERENCE.sto --map MAP.yaml --cycle T0 T1``:
a run's coordinates against measured kinematics over one gait cycle
(:mod:`openfdk.analysis.kinematics_validation`; docs/outputs.md).

Writes validation.csv, validation.md and validation.png (unless ``--no-plot``) to
``--out`` (default RUN_DIR/validation) and prints the short table. Kept apart from
:mod:`openfdk.cli.commands`, which only registers it.
"""

from __future__ import annotations

import sys
from pathlib import Path

from . import argtypes
from .argtypes import _display_arguments


def _cmd_validate_kinematics(args):
    from ..analysis.kinematics_validation import text_table, validate_kinematics, write_validation

    if args.out is not None and not str(args.out).strip():
        raise ValueError("the output is empty (--out ''); give a folder name")
    result = validate_kinematics(args.run_dir, args.reference, args.map, tuple(args.cycle), args.toe_off,
                                 args.reference_time, args.align_by)
    figure = None
    if not args.no_plot:
        from ..analysis.kinematics_validation import describe
        from ..plots.kinematics_validation import validation_figure

        figure = validation_figure(result, caption=describe(result))
    out = Path(args.out) if args.out else Path(args.run_dir) / "validation"
    paths = write_validation(result, out, figure)
    for note in result.notes:
        print(f"openfdk: warning: {note}", file=sys.stderr)
    if not getattr(args, "quiet", False):
        lo, hi = result.covered
        print(f"validate-kinematics: {result.run_dir} vs {result.reference_path.name}, cycle "
              f"{result.cycle[0]:g}–{result.cycle[1]:g} s (run covers {lo:.1f}–{hi:.1f} %; reference time as "
              f"{result.time_mode})")
        if result.alignment:
            print(f"  {result.alignment}")
        print(text_table(result))
        print(f"  -> {', '.join(str(p) for p in paths)}")
    return 0


def add_validate_parser(sub):
    """Register ``validate-kinematics`` on the main parser's subparsers."""
    v = sub.add_parser(
        "validate-kinematics", help="a run's coordinates against measured kinematics over a gait cycle "
                                    "(RMSD, offset, r² per DOF; table and figure)",
        description="Compare a run's coordinates (coordinates.csv, FDK DOFs, measures.csv) with a measured "
                    "reference (OpenSim .sto/.mot, time in %% of the gait cycle or in s) over one gait cycle: per DOF "
                    "the mean offset, the RMSD, the RMSD with the offset removed and r², in mm and degrees. Writes "
                    "validation.csv, validation.md and validation.png (docs/outputs.md).")
    v.add_argument("run_dir", help="output folder of openfdk run / kinematics")
    v.add_argument("reference", help="measured kinematics: an OpenSim storage file (.sto/.mot), SI or degrees")
    v.add_argument("--map", required=True, metavar="MAP.yaml",
                   help="YAML: reference column -> {coordinate: NAME, unit: m|mm|rad|deg, scale: 1, label: TEXT}")
    v.add_argument("--cycle", required=True, nargs=2, type=argtypes.finite, metavar=("T0", "T1"),
                   help="heel strike and the next heel strike of the same foot (s, the run's time): 0 and 100 %%")
    v.add_argument("--toe-off", type=argtypes.finite, default=None, metavar="T",
                   help="toe-off (s): the stance/swing split marked in the figure")
    v.add_argument("--reference-time", choices=["auto", "percent", "seconds"], default="auto",
                   help="the reference's time column: %% of the gait cycle or s (default auto: %% when every time "
                        "lies in [0, 100] and they span at least 50)")
    v.add_argument("--align-by", default=None, metavar="COLUMN",
                   help="shift the reference's cycle phase (within ±25 %%) to best match this column (r²), e.g. a "
                        "flexion the model tracks, when the reference's 0 %% is not the run's heel strike")
    v.add_argument("--out", default=None, help="folder of validation.csv/.md/.png (default RUN_DIR/validation)")
    v.add_argument("--no-plot", action="store_true", help="do not draw validation.png")
    _display_arguments(v, progress=False)
    v.set_defaults(func=_cmd_validate_kinematics)
