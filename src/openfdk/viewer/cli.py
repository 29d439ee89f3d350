"""The ``openfdk view`` sub-command (registered by :func:`openfdk.cli.commands.build_parser`)."""

from __future__ import annotations


def _cmd_view(args):
    from ..cli.outputs import refuse_empty_out
    from . import write_view

    refuse_empty_out(args)
    out = write_view(args.result_dir, args.out, model=args.model, max_vertices=args.max_vertices, start=args.start,
                     end=args.end)
    size = out.stat().st_size / 1e6
    if not getattr(args, "quiet", False):
        print(f"view: {out} ({size:.1f} MB); open it in a web browser (works offline)")
    return 0


def add_view_parser(sub):
    from ..cli.argtypes import _display_arguments

    v = sub.add_parser("view", help="write a self-contained 3D viewer (HTML) of a result folder",
                       description="Write one self-contained HTML file (works offline) showing a run in 3D: bodies "
                                   "and meshes, markers, muscles and ligaments coloured by force, contact, FDK panel "
                                   "(docs/viewer.md).")
    v.add_argument("result_dir", help="folder written by 'openfdk run' (kinematics.csv, forces.csv, summary.json)")
    v.add_argument("--out", default=None, help="HTML file to write (default RESULT_DIR/view.html)")
    v.add_argument("--model", default=None, help="model file (default: the one recorded in summary.json)")
    from ..cli.argtypes import count
    from . import MIN_MESH_VERTICES

    v.add_argument("--max-vertices", type=count(MIN_MESH_VERTICES), default=4000,
                   help=f"meshes with more vertices are decimated for display (default 4000, at least "
                        f"{MIN_MESH_VERTICES})")
    from ..cli.argtypes import finite

    v.add_argument("--start", type=finite, default=None, metavar="T",
                   help="show only the frames from T s on (e.g. one gait cycle of a long trial)")
    v.add_argument("--end", type=finite, default=None, metavar="T", help="show only the frames up to T s")
    _display_arguments(v, progress=False)
    v.set_defaults(func=_cmd_view)
    return v
