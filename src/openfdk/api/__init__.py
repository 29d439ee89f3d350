"""The notebook API: load a model and a trial, run, get tables (docs/python-api.md).

    import openfdk
    model = openfdk.load_model("model.yaml")
    trial = openfdk.load_trial("trial.c3d")          # or .trc
    result = openfdk.run(model, trial)               # kinematics, inverse dynamics, FDK (the file's settings)
    settings = openfdk.load_settings("model.yaml")   # AnalysisSettings, apart from the model
    other = openfdk.run(model, trial, settings=dataclasses.replace(settings, recruitment=...))
    result.kinematics, result.forces, result.fdk     # pandas DataFrames indexed by time (s)
    result.save("out"); openfdk.read_results("out")

These functions are re-exported lazily by ``openfdk`` (``import openfdk`` stays light).
"""

from __future__ import annotations

import os
import weakref
from pathlib import Path

__all__ = ["load_model", "load_settings", "load_trial", "run", "read_results", "Result"]

RUN_OPTIONS = ("cutoff_hz", "start", "end", "progress")
#: Model -> absolute path of the file it was loaded from (recorded in summary.json, so
#: that a saved run finds its model again for figures and the OpenSim export)
_MODEL_FILES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Model -> the AnalysisSettings of the file it was loaded from (the default of run())
_MODEL_SETTINGS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


#: the import options of an OpenSim model as keywords of :func:`load_model` and
#: :func:`load_settings`: {keyword: (the command line's flag, register's parameter)}
OPENSIM_OPTIONS = {"overlay": ("--with", "overlay"), "ignore": ("--ignore", "ignore"),
                   "geometry": ("--geometry", "mesh_dirs"), "ik_tasks": ("--ik-tasks", "ik_tasks"),
                   "external_loads": ("--external-loads", "external_loads"),
                   "external_loads_cutoff_hz": ("--external-loads-cutoff", "external_loads_cutoff_hz"),
                   "motion": ("--motion", "motion"), "motion_cutoff_hz": ("--motion-cutoff", "motion_cutoff_hz"),
                   "actuators": ("--actuators", "actuators"), "joint_reaction": ("--joint-reaction", "joint_reaction")}


def _register_opensim_options(path, options):
    """Register the keywords ``options`` (:data:`OPENSIM_OPTIONS`) for the ``.osim`` at
    ``path``, as the command line's flags do; none for another file."""
    if not options:
        return
    unknown = sorted(set(options) - set(OPENSIM_OPTIONS))
    if unknown:
        import difflib

        hints = [h for k in unknown for h in difflib.get_close_matches(k, list(OPENSIM_OPTIONS), n=1)]
        raise TypeError(f"openfdk.load_model: unknown option(s) {unknown}"
                        + (f"; did you mean {', '.join(map(repr, hints))}?" if hints else "")
                        + f" (options: {list(OPENSIM_OPTIONS)})")
    from ..io.opensim import is_osim
    from ..io.opensim.overlay import osim_of, register

    overlay_options = set(OPENSIM_OPTIONS) - {"overlay"}  # they replace an overlay's keys (or add to its lists)
    if not is_osim(path) and not (osim_of(path) is not None and set(options) <= overlay_options):
        raise TypeError(f"openfdk.load_model: {sorted(options)} are options of an OpenSim model (.osim); "
                        f"{Path(path).name} is not one (give them in the model file; an overlay takes all but "
                        "'overlay')")
    kwargs = {OPENSIM_OPTIONS[k][1]: v for k, v in options.items() if v is not None}
    for key in ("ignore", "mesh_dirs"):
        if isinstance(kwargs.get(key), (str, os.PathLike)):
            kwargs[key] = (kwargs[key],)
    register(path, **kwargs)


def load_model(path, **opensim_options):
    """Read and validate a model file (YAML, docs/model-file.md, or an OpenSim ``.osim``)
    into a Model (purely physical; the file's analysis settings: :func:`load_settings`,
    used by :func:`run` by default). Raises ModelError (a ValueError) naming the file and
    the entry.

    An ``.osim`` takes the command line's import options as keywords: ``overlay`` (a
    YAML of model-file sections, ``--with``), ``ignore`` (element types, ``--ignore``),
    ``geometry`` (mesh folders), ``ik_tasks``, ``external_loads`` (OpenSim's
    ExternalLoads .xml), ``external_loads_cutoff_hz`` (Hz), ``motion`` (a .mot/.sto of
    coordinates), ``motion_cutoff_hz`` (Hz) and ``actuators`` (an OpenSim actuator
    file); e.g. ``load_model("subject.osim", motion="ik.mot", external_loads="grf.xml",
    actuators="reserves.xml")``. An overlay file (``opensim: MODEL.osim``) takes them all
    but ``overlay``: they replace its keys (``ignore`` and ``geometry`` add to its lists),
    e.g. ``load_model("dm_pt.yaml", external_loads="og3_loads.xml")`` for another trial,
    or ``motion``: with FDK DOFs, the two stages (docs/gait.md)."""
    from ..io.modelfile import load_model_and_settings

    _register_opensim_options(path, opensim_options)
    model, settings = load_model_and_settings(path)
    _MODEL_FILES[model] = str(Path(path).resolve())
    _MODEL_SETTINGS[model] = settings
    return model


def load_settings(path, **opensim_options):
    """The analysis settings of a model file (sections ``analysis``, ``recruitment``,
    ``fdk``, ``joint_reaction``): an :class:`~openfdk.model.settings.AnalysisSettings`;
    an ``.osim`` with the import options of :func:`load_model`."""
    from ..io.modelfile import load_settings as _load

    _register_opensim_options(path, opensim_options)
    return _load(path)


def load_trial(path):
    """Read a marker trial, C3D or TRC by extension, into a MarkerTrial
    (``positions (n_frames, n_markers, 3) m`` NaN where missing, ``time (n_frames,) s``,
    ``rate`` Hz, ``labels``)."""
    from ..io.trials import read_trial

    return read_trial(path)


def run(model, trial=None, settings=None, **options):
    """Kinematics then inverse dynamics with muscle recruitment; force-dependent
    kinematics when the model declares FDK DOFs (as ``openfdk run``).

    Args:
        model: a Model (:func:`load_model`) or a model file path.
        trial: a MarkerTrial (:func:`load_trial`) or a C3D/TRC path; None for a
            determinate (driven) model over its ``analysis`` interval.
        settings: AnalysisSettings (:func:`load_settings`); default: those of the file
            the model was loaded from, else the defaults. The model is not modified.
        options: ``cutoff_hz`` (marker low-pass, Hz; 0 = none; default: the model
            file's, else 6 Hz), ``start``/``end`` (analysed window, s), ``progress``
            (progress bars, default False).
    Runs with one BLAS thread (``OPENFDK_BLAS_THREADS``, :mod:`openfdk.numerics.blas`),
    the library's setting restored after.
    Returns: :class:`~openfdk.api.result.Result` — ``.kinematics``, ``.forces``,
    ``.fdk`` DataFrames indexed by time, ``.summary``, ``.failed_frames``, ``.plot()``,
    ``.view()``, ``.save(dir)``.
    """
    from ..analysis.jobs import run_job
    from ..numerics.blas import blas_threads
    from .result import Result

    unknown = sorted(set(options) - set(RUN_OPTIONS))
    if unknown:
        import difflib

        hints = [h for k in unknown for h in difflib.get_close_matches(k, RUN_OPTIONS, n=1)]
        raise TypeError(f"openfdk.run: unknown option(s) {unknown}"
                        + (f"; did you mean {', '.join(map(repr, hints))}?" if hints else "")
                        + f" (options: {list(RUN_OPTIONS)})")
    if isinstance(model, (str, os.PathLike)):
        model = load_model(model)
    model_file = _MODEL_FILES.get(model)
    if isinstance(trial, (str, os.PathLike)):
        trial = load_trial(trial)
    if settings is None:
        settings = _MODEL_SETTINGS.get(model)
    with blas_threads():  # one BLAS thread, as the commands (numerics/blas.py)
        kin, dyn, info = run_job(model, trial, cutoff_hz=options.get("cutoff_hz"),
                                 progress=bool(options.get("progress", False)),
                                 start=options.get("start"), end=options.get("end"), settings=settings)
    if model_file:
        from ..analysis.jobs import import_record

        info["model_file"] = model_file
        info.update(import_record(model_file))  # an .osim's import options: a saved run reads it again with them
    return Result.from_analysis(kin, dyn, info, model, reports=getattr(settings, "joint_reaction", ()))


def read_results(directory):
    """Load a saved run (``openfdk run --out DIR`` or ``result.save(DIR)``) as a
    :class:`~openfdk.api.result.Result`."""
    from .result import Result

    return Result.read(directory)


def __getattr__(name):
    if name == "Result":  # (imported on first use: it needs numpy and pandas)
        from .result import Result

        return Result
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
