"""YAML model files -> :class:`~openfdk.model.model.Model` and, apart from it, the
file's :class:`~openfdk.model.settings.AnalysisSettings` (sections ``analysis``,
``recruitment``, ``fdk``, ``units``; format: docs/model-file.md).

The file is data: it is read with a safe YAML loader and nothing in it is evaluated.
Lengths are in the file's declared unit (``units.length``: m, cm or mm) and angles in
``units.angle`` (rad or deg); they are converted to SI once, on reading. Every error
names the file and the entry, e.g. ``model.yaml: bodies.jaw.mass: expected a number``.

Each section is read by an explicit call to its layer's loader, in this order: the core
(:func:`openfdk.model.modelfile.read_core`: units, bodies, measures, joints,
constraints, drivers, FDK DOFs, analysis), then wrapping surfaces, muscles, ligaments,
springs, bushings, reactions, loads and recruitment (:mod:`openfdk.forces.sections`), contacts
(:mod:`openfdk.contact.sections`) and the FDK solver settings
(:mod:`openfdk.fdk.settings`).
"""

from __future__ import annotations

from pathlib import Path

from ..contact.sections import load_contacts
from ..dynamics.joint_reaction_settings import load_joint_reaction
from ..fdk.settings import load_fdk
from ..forces.actuator_section import load_actuators, load_reserves
from ..forces.data_load_section import load_external_loads
from ..forces.sections import (load_bushings, load_ligaments, load_loads, load_muscles, load_reactions,
                               load_recruitment, load_springs, load_wrapping)
from ..model.model import Model, ModelError
from ..model.modelfile import build, read_core
from ..model.settings import AnalysisSettings
from ..model.plausibility import check_model
from .yamlfile import read_yaml

#: the sections read after the core ones, in this order, each by its layer's loader
#: ``loader(builder, data, ctx)``
SECTIONS = (
    ("wrapping", load_wrapping),
    ("muscles", load_muscles),
    ("ligaments", load_ligaments),
    ("springs", load_springs),
    ("bushings", load_bushings),
    ("reactions", load_reactions),
    ("loads", load_loads),
    ("actuators", load_actuators),
    ("reserves", load_reserves),
    ("external_loads", load_external_loads),
    ("ground_reactions", lambda b, data, ctx: b.elements.__setitem__("ground_reactions", data)),
    ("recruitment", load_recruitment),
    ("contacts", load_contacts),
    ("fdk", load_fdk),
    ("joint_reaction", load_joint_reaction),
)


def model_file_data(path, parse=None) -> dict:
    """The model mapping of the file at ``path``: an OpenSim ``.osim`` imported (with the
    options registered for it in this process), an overlay YAML (an ``opensim:`` key)
    merged onto the ``.osim`` it names, else the YAML mapping itself. ``parse(path)``
    reads the YAML (default: :func:`read_yaml`; a study's cache passes its own)."""
    from .opensim.overlay import imported_model_data, overlay_model_data

    data = imported_model_data(path)
    if data is None:
        data = overlay_model_data(path, read_yaml(path, ModelError, "model file") if parse is None else parse(path))
    return data


def load_model_and_settings(path) -> tuple[Model, AnalysisSettings]:
    """Read, validate and build a model file: (the physical Model, the file's analysis
    settings). Raises ModelError naming the entry. An OpenSim ``.osim`` is read by
    :mod:`openfdk.io.opensim` (with the overlay and options registered for it by
    :func:`openfdk.io.opensim.overlay.register`); a YAML file with an ``opensim:`` key is
    an overlay on the ``.osim`` it names (docs/opensim-import.md)."""
    path = Path(path)
    from .opensim.overlay import model_source

    data = model_file_data(path)
    model, settings = built_from_data(data, path, model_source(path))
    check_model(model, path.name, settings.units["length"])  # plausibility warnings
    return model, settings


_FILE_NAME = object()  # built_from_data's default label: the file's name


def built_from_data(data, path, source, base_dir=None, label=_FILE_NAME):
    """(Model, AnalysisSettings) of the model mapping ``data`` of the file ``path``
    (relative paths from ``base_dir``, default the file's folder; ``label`` names it in
    the ground reactions' errors, default the file's name, None: ``source``). With a
    motion file's drivers, those of coordinates the model's own rows determine are left
    out (:func:`openfdk.io.opensim.motion.without_determined`) and recorded in the
    import's ``motion_not_driven``, the model built again without them, and the first
    build's warnings given only when it is the one kept. Every path from a model file
    to a Model goes through here: ``openfdk run --chunks``' workers build the case's
    mapping too (:func:`openfdk.study.case.build_case_model`)."""
    import warnings

    from .opensim.motion import is_motion_driver, without_determined

    base_dir = path.parent if base_dir is None else base_dir
    label = path.name if label is _FILE_NAME else label

    def build_from(mapping):
        return model_and_settings_from_dict(mapping, source=source, base_dir=base_dir, label=label)

    drivers = data.get("drivers") if isinstance(data, dict) else None
    if not isinstance(drivers, dict) or not any(is_motion_driver(name, entry) for name, entry in drivers.items()):
        return build_from(data)
    error, built = None, None
    with warnings.catch_warnings(record=True) as given:
        warnings.simplefilter("always")
        try:
            built = build_from(data)
        except Exception as exc:  # raised below, after its warnings
            error = exc
    undriven = None if error is not None else without_determined(built[0], data, path)
    if undriven is not None:
        from .opensim.overlay import record_import

        undriven, names = undriven
        record_import(path, "motion_not_driven", {name: "constraints" for name in names})
        return build_from(undriven)
    for w in given:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if error is not None:
        raise error
    return built


def load_model(path) -> Model:
    """The Model of a model file (its settings: :func:`load_settings`)."""
    return load_model_and_settings(path)[0]


def load_model_for_results(path, summary=None) -> Model:
    """The Model of a model file read to draw, view or export a finished run's results
    (``openfdk plot``, ``view``, ``export-opensim``, :meth:`RunResults.model`). Its input
    checks' warnings (:class:`~openfdk.model.plausibility.PlausibilityWarning`: the
    model's plausibility, ground reactions that look unfiltered, ...) are not given
    again: they concern the analysis, which gave them when it ran. Errors are raised as
    by :func:`load_model`. ``summary``: the run's summary.json; an ``.osim`` that is the
    run's model is read with the options the run read it with (``--ignore``, ``--with``,
    ``--motion`` …, ``input.opensim_import.options``)."""
    import warnings

    from ..model.plausibility import PlausibilityWarning

    _register_run_options(path, summary)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlausibilityWarning)
        return load_model(path)


def _register_run_options(path, summary):
    """The run's OpenSim import options (summary.json) registered for ``path`` when it is
    the run's ``.osim``, or its overlay file (whose ``--motion`` the run read)."""
    from .opensim import is_osim
    from .opensim.overlay import osim_of, register_record

    inp = summary.get("input") if isinstance(summary, dict) else None
    if not isinstance(inp, dict) or not (is_osim(path) or osim_of(path) is not None):
        return
    recorded = inp.get("model_file") or inp.get("model")
    imported = inp.get("opensim_import")
    if not isinstance(recorded, str) or not isinstance(imported, dict):
        return
    try:
        same = Path(recorded).resolve() == Path(path).resolve()
    except OSError:
        return
    if same:
        register_record(path, imported.get("options"))


def load_settings(path) -> AnalysisSettings:
    """The analysis settings of a model file (the whole file is read and validated)."""
    return load_model_and_settings(path)[1]


def model_and_settings_from_dict(data, source="<dict>", base_dir=None, label=None) -> tuple[Model, AnalysisSettings]:
    """(Model, AnalysisSettings) from the parsed YAML mapping (see docs/model-file.md);
    the ``ground_reactions`` section checked against the model and normalised
    (:func:`openfdk.io.ground_reactions.check_spec`; errors name ``label``, default
    ``source``)."""
    b, ctx = read_core(data, source, base_dir, [name for name, _ in SECTIONS])
    for name, loader in SECTIONS:
        if name in data:
            loader(b, data[name], ctx)
    model, settings = build(b, ctx), b.settings()
    if settings.ground_reactions:
        from dataclasses import replace

        from .ground_reactions import check_spec

        settings = replace(settings, ground_reactions=check_spec(settings.ground_reactions, model, label or source))
    return model, settings


def model_from_dict(data, source="<dict>", base_dir=None) -> Model:
    """The Model of a parsed YAML mapping (its settings:
    :func:`model_and_settings_from_dict`)."""
    return model_and_settings_from_dict(data, source, base_dir)[0]
