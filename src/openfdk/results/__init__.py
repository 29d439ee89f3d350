"""The one results layer: a run's result folder read back (``kinematics.csv``,
``forces.csv``, ``measures.csv``, ``summary.json``; the ``.sto`` twins are written from the
same tables) for every reader — the Python API, the figures (:mod:`openfdk.plots`), the
viewer (:mod:`openfdk.viewer`) and the OpenSim export (:mod:`openfdk.io.osim`).

* :mod:`.run` — :class:`~.run.RunResults`: the tables as pandas DataFrames, the summary,
  the run's model, saving; :func:`~.run.read_results`, :func:`~.run.read_summary`.
* :mod:`.columns` — the fast reader: a table's columns parsed when first used
  (:func:`~.columns.read_columns`, :func:`~.columns.read_run_tables`), for the viewer's
  long runs.
* :mod:`.metrics` — agreement of a computed and a measured time series.

Nothing here imports the figures, the viewer or the command line.
"""
