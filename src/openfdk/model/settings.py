"""Analysis settings: how a model is analysed, kept apart from what the model is.

The model file carries both (sections ``analysis``, ``recruitment``, ``fdk``), but the
physical description (:class:`~openfdk.model.model.Model`: bodies, joints, markers,
force elements) never depends on them, and an analysis may be run with other settings
than the file's (e.g. ``run_fdk(model, …, settings=…)``, ``jacobian="central"``).
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class AnalysisSettings:
    """kinematics : the model file's ``analysis`` section (start, end, frames (s, s, int)
    of determinate kinematics and the analysis window; marker_cutoff_hz (Hz));
    recruitment : :class:`openfdk.forces.elements.RecruitmentSettings` or None (the
    default criterion); fdk : the ``fdk`` section (tolerance, max_iterations, jacobian,
    …; see :func:`openfdk.fdk.settings.fdk_settings`); units : the file's declared
    units {"length": …, "angle": …}; ground_reactions : the force plates' assignment
    to bodies (:mod:`openfdk.io.ground_reactions`), {} when the trial's plates are not
    used."""

    kinematics: dict = field(default_factory=dict)
    recruitment: object = None
    fdk: dict = field(default_factory=dict)
    units: dict = field(default_factory=dict)
    ground_reactions: dict = field(default_factory=dict)
