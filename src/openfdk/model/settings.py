"""Analysis settings: how a model is analysed, kept apart from what the model is.

The model file carries both (sections ``analysis``, ``recruitment``, ``fdk``), but the
physical description (:class:`~openfdk.model.model.Model`: bodies, joints, markers,
force elements) never depends on them, and an analysis may be run with other settings
than the file's (e.g. ``run_fdk(model, …, settings=…)``, ``jacobian="central"``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields


def checked_keywords(cls):
    """Class decorator for a settings dataclass: an unknown keyword (a typo) raises a
    ValueError naming the class and the key, with the closest field name
    (``FDKSettings: unknown key 'tolerence'; did you mean 'tolerance'?``), instead of
    Python's ``TypeError: __init__() got an unexpected keyword argument``. Also covers
    :func:`dataclasses.replace`, which calls the constructor."""
    init = cls.__init__

    def __init__(self, *args, **kwargs):
        allowed = [f.name for f in fields(cls) if f.init]
        for key in kwargs:
            if key not in allowed:
                from ..io.yamlfile import unknown_key

                hint = unknown_key(key, allowed)[len("unknown key"):]  # "; did you mean 'x'?"
                raise ValueError(f"{cls.__name__}: unknown key {key!r}{hint}")
        init(self, *args, **kwargs)

    __init__.__doc__, __init__.__wrapped__ = init.__doc__, init
    cls.__init__ = __init__
    return cls


@checked_keywords
@dataclass(frozen=True)
class AnalysisSettings:
    """kinematics : the model file's ``analysis`` section (start, end, frames (s, s, int)
    of determinate kinematics and the analysis window; marker_cutoff_hz (Hz));
    recruitment : :class:`openfdk.forces.elements.RecruitmentSettings` or None (the
    default criterion); fdk : the ``fdk`` section, an
    :class:`openfdk.fdk.settings.FDKSettings` (tolerance, max_iterations, jacobian, …; a
    dict of its fields is converted, an unknown key refused with a did-you-mean); units : the file's declared
    units {"length": …, "angle": …}; ground_reactions : the force plates' assignment
    to bodies (:mod:`openfdk.io.ground_reactions`), {} when the trial's plates are not
    used; joint_reaction : the joint loads reported as OpenSim's JointReaction reports
    them, :class:`~openfdk.dynamics.joint_reaction_settings.JointReport` each (the model
    file's ``joint_reaction`` section), () for OpenSim's defaults."""

    kinematics: dict = field(default_factory=dict)
    recruitment: object = None
    fdk: object = None
    units: dict = field(default_factory=dict)
    ground_reactions: dict = field(default_factory=dict)
    joint_reaction: tuple = ()

    def __post_init__(self):
        from ..fdk.settings import FDKSettings

        fdk = self.fdk
        if fdk is None or isinstance(fdk, dict):
            object.__setattr__(self, "fdk", FDKSettings(**(fdk or {})))
        elif not isinstance(fdk, FDKSettings):
            raise ValueError(f"AnalysisSettings.fdk: expected an FDKSettings or a dict of its fields, got "
                             f"{type(fdk).__name__}")
