"""``openfdk import-opensim MODEL.osim --out DIR``: the imported model as a readable
openfdk model file (``DIR/<model>.yaml``) with its meshes copied to ``DIR/Geometry``.

The file is the mapping the ``.osim`` reader builds (:mod:`.to_model`), so it loads to
the same model: the same bodies, frames, joints, coordinates, functions and markers, in
SI units (``units: {length: m, angle: rad}``). Lists of numbers are written on one line;
floats with Python's shortest round-trip representation, so nothing is rounded.
"""

from __future__ import annotations

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


def write_imported(data, out_dir, source_name, info=None):
    """Write ``data`` (an imported model mapping) as ``out_dir/<name>.yaml`` and copy its
    visual meshes into ``out_dir/Geometry`` (paths in the file made relative). Returns
    the model file's path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    data = _copy_meshes(data, out_dir)
    name = f"{data.get('name') or Path(source_name).stem}.yaml"
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


def _copy_meshes(data, out_dir):
    """The mapping with every visual mesh copied to out_dir/Geometry (unique names)."""
    bodies = {}
    used = {}
    for bname, body in data["bodies"].items():
        body = dict(body)
        if "visual" in body:
            visuals = []
            for v in body["visual"]:
                src = Path(v["mesh"])
                target = used.get(str(src))
                if target is None:
                    target = f"Geometry/{src.name}"
                    k = 1
                    while target in used.values():
                        target = f"Geometry/{src.stem}_{k}{src.suffix}"
                        k += 1
                    (out_dir / "Geometry").mkdir(exist_ok=True)
                    shutil.copyfile(src, out_dir / target)
                    used[str(src)] = target
                visuals.append({**v, "mesh": target})
            body["visual"] = visuals
        bodies[bname] = body
    return {**data, "bodies": bodies}
