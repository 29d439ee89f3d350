"""``openfdk import-opensim MODEL.osim --out DIR``: the imported model as a readable
openfdk model file (``DIR/<model>.yaml``) with its meshes copied to ``DIR/Geometry``.

The file is the mapping the ``.osim`` reader builds (:mod:`.to_model`), so it loads to
the same model: the same bodies, frames, joints, coordinates, functions and markers, in
SI units (``units: {length: m, angle: rad}``). Lists of numbers are written on one line;
floats with Python's shortest round-trip representation, so nothing is rounded.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import yaml


class _Dumper(yaml.SafeDumper):
    """Short lists of numbers in flow style; everything else in block style."""


def _represent_list(dumper, data):
    flat = all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in data)
    nested = all(isinstance(x, list) and all(isinstance(y, (int, float)) for y in x) for x in data) and data
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=bool(flat or nested))


def _represent_float(dumper, value):
    if value != value or value in (float("inf"), float("-inf")):
        return dumper.represent_float(value)
    return dumper.represent_scalar("tag:yaml.org,2002:float", repr(float(value)))


_Dumper.add_representer(list, _represent_list)
_Dumper.add_representer(float, _represent_float)


def write_imported(data, out_dir, source_name, info=None, force=False):
    """Write ``data`` (an imported model mapping) as ``out_dir/<name>.yaml`` and copy its
    visual meshes into ``out_dir/Geometry`` (paths in the file made relative). Returns
    the model file's path. Files of an earlier import (the model file, a mesh of the same
    name) are overwritten only with ``force``; otherwise, and for a target that is a
    folder, OutputDirError names it before anything is written."""
    from ..outdir import OutputDirError

    out_dir = Path(out_dir)
    name = data.get("name") or Path(source_name).stem
    if len(name) > 100:  # a model name too long for a file name: the .osim's own name
        name = Path(source_name).stem
    name = f"{name}.yaml"
    meshes = _mesh_targets(data)
    for target in [name, "Geometry"] + sorted(set(meshes.values())):
        path = out_dir / target
        if target == "Geometry":
            # a symlink would put the meshes outside --out
            if os.path.lexists(path) and (path.is_symlink() or not path.is_dir()):
                raise OutputDirError(f"output folder {str(out_dir)!r}: {target} is not a folder of its own "
                                     "(a file or a symlink)")
            continue
        if path.is_dir():
            raise OutputDirError(f"output folder {str(out_dir)!r}: {target} is a folder")
        if os.path.lexists(path) and not force:
            raise OutputDirError(f"output folder {str(out_dir)!r} already holds {target} (an earlier import?); "
                                 "use --force to overwrite it or choose another --out")
    out_dir.mkdir(parents=True, exist_ok=True)
    data = _copy_meshes(data, out_dir, meshes)
    header = [f"# openfdk model imported from the OpenSim model {source_name} by openfdk import-opensim.",
              "# Units are SI (m, rad, kg); joints of type custom are OpenSim's SpatialTransforms",
              "# (docs/opensim-import.md)."]
    from collections import Counter

    counts = Counter(d["type"] for d in (info or {}).get("dropped", []))
    if counts:
        header.append("# left out (--ignore): " + ", ".join(f"{n} {kind}" for kind, n in counts.items()))
    text = "\n".join(header) + "\n" + yaml.dump(data, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=100)
    path = out_dir / name
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path


def _mesh_files(data):
    """Every mesh file the mapping names: bodies' visual meshes and contact surfaces."""
    for body in data["bodies"].values():
        for v in body.get("visual", ()):
            yield Path(v["mesh"])
    for contact in (data.get("contacts") or {}).values():
        for side in ("vertices", "surface"):
            yield Path(contact[side]["mesh"])
            if "thickness" in contact[side]:  # the bone behind a cartilage of variable thickness
                yield Path(contact[side]["thickness"]["back_mesh"])


def _mesh_targets(data):
    """{mesh file: its path in the output folder, "Geometry/<name>"} (unique names)."""
    used = {}
    for src in _mesh_files(data):
        if str(src) not in used:
            target = f"Geometry/{src.name}"
            k = 1
            while target in used.values():
                target = f"Geometry/{src.stem}_{k}{src.suffix}"
                k += 1
            used[str(src)] = target
    return used


def _copy_meshes(data, out_dir, targets):
    """The mapping with every visual and contact mesh copied to out_dir/Geometry (``targets``:
    :func:`_mesh_targets`). A file is copied to a temporary name and renamed, so that a
    symlink already at the target is replaced rather than written through."""
    bodies = {}
    for bname, body in data["bodies"].items():
        body = dict(body)
        if "visual" in body:
            body["visual"] = [{**v, "mesh": targets[str(Path(v["mesh"]))]} for v in body["visual"]]
        bodies[bname] = body
    def side_copied(spec):
        spec = {**spec, "mesh": targets[str(Path(spec["mesh"]))]}
        if "thickness" in spec:
            spec["thickness"] = {**spec["thickness"],
                                 "back_mesh": targets[str(Path(spec["thickness"]["back_mesh"]))]}
        return spec

    contacts = {name: {**c, **{side: side_copied(c[side]) for side in ("vertices", "surface")}}
                for name, c in (data.get("contacts") or {}).items()}
    for src, target in targets.items():
        dest = out_dir / target
        dest.parent.mkdir(exist_ok=True)
        try:
            if os.path.samefile(src, dest):
                continue  # --out is the model's own folder: the mesh is already there
        except OSError:  # no such file (yet)
            pass
        tmp = dest.with_name(f".{dest.name}.tmp")
        shutil.copyfile(src, tmp)
        os.replace(tmp, dest)
    return {**data, "bodies": bodies, **({"contacts": contacts} if contacts else {})}
