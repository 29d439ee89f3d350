"""Runs shared by the output tests (figures, OpenSim files, Python API): each is made
once per test session through the command line."""

import pytest

from openfdk.cli import main


@pytest.fixture(scope="session")
def slider_run(tmp_path_factory, request):
    out = tmp_path_factory.mktemp("slider") / "run"
    model = request.config.rootpath / "examples" / "slider_crank.yaml"
    assert main(["run", str(model), "--out", str(out), "--no-progress"]) == 0
    return out, model


@pytest.fixture(scope="session")
def mandible_run(tmp_path_factory):
    """The mandible study's FDK model on a virtual subject (coarse meshes), 7 frames of
    open–close, through `openfdk run` (figures included)."""
    from openfdk.mandible.experiment import record_experiment
    from openfdk.mandible.generator import create_subject
    from openfdk.mandible.models import write_models
    from openfdk.mandible.registration import register_braces
    from openfdk.mandible.subject import load_subject

    d = tmp_path_factory.mktemp("mandible")
    subject_dir = create_subject(d / "subject", resolution="coarse")
    record_experiment(subject_dir, tasks=("open_close",), cycles=1)
    subject = load_subject(subject_dir)
    models = write_models(subject, register_braces(subject, subject_dir / "trials" / "reference.c3d"), d / "models")
    out = d / "run"
    assert main(["run", str(models["fdk"]), str(subject_dir / "trials" / "open_close.c3d"), "--out", str(out),
                 "--end", "0.06", "--no-progress"]) == 0
    return out, models["fdk"]


