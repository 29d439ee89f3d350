"""Study settings a subject folder gives the mandible study (issue 28): the FDK
contacts' max_depth (subject.yaml ``contact: {max_depth}``), and a penetration warning
that names the task and the model and says where to raise the depth."""

import warnings

import pytest
import yaml

from openfdk.contact.limits import ContactDepthWarning
from openfdk.mandible.experiment import record_experiment
from openfdk.mandible.generator import create_subject
from openfdk.mandible.models import write_models
from openfdk.mandible.registration import register_from_braces
from openfdk.mandible.study import analyse_trial
from openfdk.mandible.subject import load_subject


@pytest.fixture(scope="module")
def shallow(tmp_path_factory):
    """A coarse virtual subject with one open–close cycle whose contacts ignore
    vertices deeper than 0.02 mm (subject.yaml contact.max_depth)."""
    folder = create_subject(tmp_path_factory.mktemp("depth") / "subject", resolution="coarse")
    record_experiment(folder, tasks=("open_close",), cycles=1)
    with open(folder / "subject.yaml", "a", encoding="utf-8") as fh:
        fh.write("\ncontact: {max_depth: 0.02}\n")
    return load_subject(folder)


def test_contact_max_depth_reaches_the_fdk_model(shallow, tmp_path):
    """0.02 in the subject's length unit (mm) is 2e-5 m; the FDK model file (mm) holds
    0.02 on both contacts; the POP model has no contacts."""
    assert shallow.protocol.contact_max_depth == pytest.approx(2e-5)
    paths = write_models(shallow, register_from_braces(shallow), tmp_path / "models")
    fdk = yaml.safe_load(paths["fdk"].read_text())
    assert {c["max_depth"] for c in fdk["contacts"].values()} == {0.02}
    assert "contacts" not in yaml.safe_load(paths["pop"].read_text())


def test_depth_warning_names_the_task_the_model_and_the_setting(shallow, tmp_path):
    """The condyles press ≳ 0.05 mm into the fossae under the joint load (10 GN/m³,
    a few N over a few mm²), beyond 90 % of 0.02 mm: one ContactDepthWarning per
    contact, naming the task and the FDK model and the subject.yaml setting; the
    messages are in the run's ``warnings``."""
    reg = register_from_braces(shallow)
    models = write_models(shallow, reg, tmp_path / "models")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _, runs = analyse_trial(shallow, reg, models, shallow.protocol.trial("open_close").file, tmp_path / "oc",
                                start=0.5, end=0.9, task="open_close")
    depth = [str(w.message) for w in caught if issubclass(w.category, ContactDepthWarning)]
    assert depth and all(m.startswith("task 'open_close', FDK model: contact 'tmj_") for m in depth)
    assert all("contact: {max_depth: MM}" in m and "0.02 mm" in m for m in depth)
    assert runs["FDK"]["warnings"] and not any("max_depth" in m for m in runs["POP"]["warnings"])
