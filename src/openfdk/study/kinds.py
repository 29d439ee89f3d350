"""Case kinds: how the inputs of one study case become a model mapping and a trial.

A study crosses the entries of some input sections of its file (for the built-in
``model`` kind: ``models`` × ``trials``) with its parameter sets. A :class:`CaseKind`
names those sections and a ``prepare`` function, given as an importable
``"module:function"`` string so that a worker process on any machine can find it.
``prepare(case) -> PreparedCase`` runs in the worker and returns the *parsed model-file
mapping* (before overrides), the folder its relative paths are relative to and the
trial file. Everything after that (overrides, model building, chunking, writing the
case folder) is shared by all kinds.

Adding a kind (e.g. the mandible study's "subject folder + task + model kind")::

    register_case_kind(CaseKind(
        name="subject", inputs=("subjects", "tasks", "model_kinds"),
        paths=("subjects",), prepare="mylab.cases:prepare_subject_case"))

and a study file then says ``kind: subject`` with sections ``subjects``, ``tasks`` and
``model_kinds``. The study file must be loaded after the kind is registered, in the
process that drives the study (workers only import ``prepare``).
"""

from __future__ import annotations

import copy
import importlib
from dataclasses import dataclass
from pathlib import Path

from ..io.fingerprint import file_stamp
from ..io.yamlfile import read_yaml
from ..model.errors import ModelError


@dataclass(frozen=True)
class PreparedCase:
    """model_data : the model-file mapping before overrides (file units); source : name
    used in messages; base_dir : folder that relative paths in the mapping (meshes) are
    relative to; trial : C3D file path, or None for determinate kinematics."""

    model_data: dict
    source: str
    base_dir: Path
    trial: str | None


@dataclass(frozen=True)
class CaseKind:
    """name : the study file's ``kind``; inputs : study sections whose entries are
    crossed to form cases, in order (each a mapping name -> value, or a list); optional :
    those of ``inputs`` a study may omit; paths : those whose values are file or folder
    paths relative to the study file (checked to exist, content-hashed into the case
    fingerprint); prepare : ``"module:function"``, ``prepare(case) -> PreparedCase``;
    cheap_prepare : prepare is fast enough to call once per input combination in the
    driver, so override paths are checked before anything is run."""

    name: str
    inputs: tuple
    optional: tuple = ()
    paths: tuple = ()
    prepare: str = ""
    cheap_prepare: bool = False


CASE_KINDS: dict = {}


def register_case_kind(kind: CaseKind) -> CaseKind:
    """Add (or replace) a case kind. Returns it."""
    if not kind.prepare or ":" not in kind.prepare:
        raise ValueError(f"case kind {kind.name!r}: prepare must be 'module:function', got {kind.prepare!r}")
    unknown = [s for s in (*kind.optional, *kind.paths) if s not in kind.inputs]
    if unknown:
        raise ValueError(f"case kind {kind.name!r}: {unknown} are not among its inputs {list(kind.inputs)}")
    CASE_KINDS[kind.name] = kind
    return kind


def import_callable(spec: str):
    """The function named by ``"package.module:function"``."""
    module, _, name = spec.partition(":")
    try:
        fn = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"cannot import {spec!r} (expected 'module:function'): {exc}") from None
    if not callable(fn):
        raise ValueError(f"{spec!r} is not callable")
    return fn


#: parsed model files of this process: file_stamp -> mapping (read_model_mapping), at
#: most MAPPING_SLOTS, the oldest dropped
_MAPPINGS: dict = {}
MAPPING_SLOTS = 8


def read_model_mapping(path) -> dict:
    """The model mapping of a model file (:func:`openfdk.io.modelfile.model_file_data`:
    YAML, an ``.osim`` imported, or an overlay YAML merged onto its ``.osim``), a fresh
    copy that the caller may change. A YAML file is parsed once per process and content
    (its :func:`~openfdk.io.fingerprint.file_stamp`: path, size, modification time), so
    the cases of a study that share a model file do not parse it again."""
    from ..io.modelfile import model_file_data

    return model_file_data(Path(path), _parsed_yaml)


def _parsed_yaml(path) -> dict:
    """A copy of the YAML mapping of ``path`` (safe loader; errors name the file), from
    this process's cache of parsed model files."""
    stamp = file_stamp(path)
    data = _MAPPINGS.get(stamp) if stamp is not None else None
    if data is None:
        data = read_yaml(path, ModelError, "model file")
        if not isinstance(data, dict):
            raise ModelError(f"{path.name}: a model file must contain a mapping of sections")
        if stamp is not None:
            _MAPPINGS[stamp] = data
            while len(_MAPPINGS) > MAPPING_SLOTS:
                _MAPPINGS.pop(next(iter(_MAPPINGS)))  # the oldest
    return copy.deepcopy(data)


def prepare_model_case(case) -> PreparedCase:
    """The ``model`` kind: ``case.inputs["models"]`` is a model file (YAML, an OpenSim
    ``.osim`` or an overlay YAML naming one), ``trials`` (optional) a C3D or TRC file. An
    ``.osim``'s command-line import options (``--with``, ``--ignore``, …) come with the
    case (``import_options``), registered here before the import: a worker process of
    ``openfdk run --chunks`` imports the model as the command did."""
    from ..io.opensim.overlay import register_options

    path = Path(case.inputs["models"])
    if case.import_options is not None:
        register_options(path, case.import_options)
    trial = case.inputs.get("trials")
    return PreparedCase(read_model_mapping(path), path.name, path.parent, None if trial is None else str(trial))


register_case_kind(CaseKind(
    name="model", inputs=("models", "trials"), optional=("trials",), paths=("models", "trials"),
    prepare="openfdk.study.kinds:prepare_model_case", cheap_prepare=True,
))
