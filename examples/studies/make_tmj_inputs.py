"""Write the inputs of the TMJ example studies next to this file (folder ``tmj/``): the
synthetic TMJ-like FDK model (two spherical condyles in elastic-foundation contact with
the TMJ planes, 3 FDK DOFs, 6 ligament elements, 24 Hill muscles; openfdk.fixtures.synthetic_jaw),
its meshes, a 300-frame and a 2000-frame open–close trial at 100 Hz (0.1 mm marker noise).

    python examples/studies/make_tmj_inputs.py
    openfdk study examples/studies/tmj_ligament_parameter_study.yaml --out tmj-study
"""

from pathlib import Path

import yaml

from openfdk.io.c3d import write_c3d
from openfdk.fixtures.synthetic_jaw import jaw_fdk_model_dict, jaw_markers, write_jaw_meshes


def make_tmj_inputs(folder):
    folder = Path(folder)
    write_jaw_meshes(folder / "meshes")
    (folder / "tmj_fdk.yaml").write_text(yaml.safe_dump(jaw_fdk_model_dict("meshes"), sort_keys=False))
    for name, frames in (("open_close", 300), ("long_open_close", 2000)):
        _t, labels, x, _ = jaw_markers(frames, noise=1e-4, seed=1)
        write_c3d(folder / f"{name}.c3d", labels, x, 100.0)
    return folder


if __name__ == "__main__":
    print(f"wrote {make_tmj_inputs(Path(__file__).parent / 'tmj')}")
