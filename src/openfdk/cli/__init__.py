"""The ``openfdk`` command line (docs/cli.md): the parser and the commands
(:mod:`.commands`), the output commands ``plot`` and ``export-opensim`` (:mod:`.outputs`),
argument types (:mod:`.argtypes`) and the kinematics demo (:mod:`.demo_kinematics`).

``openfdk.cli.main`` is the console script's entry point (pyproject.toml).
"""

from .commands import main

__all__ = ["main"]
