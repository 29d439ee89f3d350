"""OpenSim 1.x and 2.x models (``OpenSimDocument Version`` < 30000), upgraded by OpenSim.

openfdk reads the layouts of OpenSim 3 (``Version`` 30000–39999) and 4 (≥ 40000). Older
files name their elements and properties otherwise (``Vmax`` for
``max_contraction_velocity``, ``MusclePointSet`` for the ``GeometryPath``, CustomJoints
without a ``SpatialTransform``, …). OpenSim's own reader upgrades them when it loads
them, property by property. openfdk does not repeat that table: when OpenSim's Python
package is installed, the file is loaded and written again by OpenSim, in a child
process (OpenSim's C++ may abort on a bad file; the child's failure is an OsimError),
and openfdk reads what it writes. Without OpenSim the message says how to upgrade the
file. Measured on the 56 such files of opensim-core's repository: OpenSim upgrades 51.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

from .errors import OsimError

#: the oldest OpenSimDocument Version openfdk reads itself (OpenSim 3.0)
OLDEST_READ = 30000
#: seconds OpenSim may take to load and write a model
TIMEOUT_S = 120

_CHILD = """
import sys
import opensim
opensim.Logger.setLevelString("Off")
model = opensim.Model(sys.argv[1])
model.printToXML(sys.argv[2])
print(opensim.__version__)
"""


def upgraded_copy(path: Path, version: int, folder: Path, source: str) -> tuple[Path, str]:
    """(the file OpenSim writes, OpenSim's version) for the old model ``path``
    (``version`` < OLDEST_READ), written into ``folder`` (a temporary directory; its
    name is ``path``'s). OsimError naming ``source`` when OpenSim is not installed or
    cannot read the file."""
    release = f"OpenSim {version // 10000}.x"
    if importlib.util.find_spec("opensim") is None:
        raise OsimError(f"{source}: OpenSimDocument Version {version} is an {release} file; openfdk reads "
                        f"Version {OLDEST_READ} (OpenSim 3.0) and later. Install OpenSim's Python package "
                        f"('pip install opensim') and openfdk upgrades it, or open the model in OpenSim 4 "
                        f"and save it (File > Save Model As)")
    target = Path(folder) / Path(path).name
    try:
        done = subprocess.run([sys.executable, "-c", _CHILD, str(path), str(target)], capture_output=True,
                              text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise OsimError(f"{source}: OpenSim did not upgrade this {release} file within {TIMEOUT_S} s") from None
    if done.returncode != 0 or not target.is_file():
        lines = [line.strip() for line in (done.stderr or "").splitlines() if line.strip()]
        why = lines[-1][:200] if lines else f"exit status {done.returncode}"
        raise OsimError(f"{source}: OpenSimDocument Version {version} is an {release} file, and OpenSim could "
                        f"not upgrade it: {why}")
    return target, (done.stdout.strip().splitlines() or ["?"])[-1]
