"""The mandible study: subject folders, the virtual subject and the virtual experiment.

* :func:`load_subject` — read and validate a subject folder (docs/subject-folder.md).
* :func:`create_subject` — write a generated (virtual) subject folder.
* :func:`record_experiment` — the virtual experiment: C3D trials + ground truth
  (docs/virtual-experiment.md).
* :func:`record_realistic` — the virtual experiment as real recordings behave
  (docs/virtual-experiment.md, "Realistic recordings").
* :func:`measured_condyle_kinematics` — condyle tops as the dental braces measure them.
* The study and its steps: :mod:`openfdk.mandible.study` (docs/mandible-study.md).
"""

from .experiment import (
           load_truth,
           measured_condyle_kinematics,
           record_experiment,
           rigid_fit,
)
from .generator import create_subject
from .realistic import record_realistic
from .subject import Subject, SubjectError, load_subject
from .truth import TruthOptions

__all__ = ["Subject", "SubjectError", "TruthOptions", "create_subject", "load_subject",
           "load_truth", "measured_condyle_kinematics", "record_experiment", "record_realistic", "rigid_fit"]
