"""Issue 30, item 2 (builder path): models built in Python — the ModelBuilder, the
force-element and contact adders — follow the model file's rule for names
(openfdk.model.names): no '/', '\\', '..', control characters or XML's reserved
characters, since names become file names and XML in export-opensim. A Model made
without the builder is checked by export-opensim before anything is written."""

import dataclasses

import numpy as np
import pytest

from openfdk.forces.elements import add_external_load, add_spring, add_wrap_surface
from openfdk.model.builder import ModelBuilder
from openfdk.model.model import ModelError
from openfdk.model.timefunctions import Polynomial

BAD = ["a/b", "a\\b", "a..b", "a\x01b", "a\x7fb", "a<b", "a>b", "a&b", 'a"b']


def _pendulum(name="bob"):
    """A one-body pendulum builder (the builder module's example)."""
    b = ModelBuilder("pendulum")
    b.add_body(name, mass=1.0, inertia=[1e-3, 1e-3, 1e-3], position=[0, 0, -0.5])
    b.add_frame(name, "pivot", [0, 0, 0.5])
    b.add_joint("pin", "revolute", parent="ground.origin", child=f"{name}.pivot")
    b.add_driver("swing", b.angles("ground.origin", f"{name}.origin"), Polynomial([0, 1.0]), components=[2])
    return b


ADDERS = {
    "body": lambda b, n: b.add_body(n, 1.0, [1e-3] * 3),
    "frame/point": lambda b, n: b.add_frame("bob", n, [0, 0, 0]),
    "marker": lambda b, n: b.add_marker(n, "bob", [0, 0, 0]),
    "measure": lambda b, n: b.add_measure(n, b.distance("ground.origin", "bob.origin")),
    "joint": lambda b, n: b.add_joint(n, "spherical", parent="ground.origin", child="bob.pivot"),
    "constraint": lambda b, n: b.add_constraint(n, b.distance("ground.origin", "bob.origin"), 0.5),
    "driver": lambda b, n: b.add_driver(n, b.distance("ground.origin", "bob.origin"), Polynomial([0.5])),
    "FDK DOF": lambda b, n: b.add_fdk_dof(n, b.distance("ground.origin", "bob.origin")),
    "force element": lambda b, n: add_spring(b, n, b.distance("ground.origin", "bob.origin"), 10.0),
    "wrapping surface": lambda b, n: add_wrap_surface(b, n, "sphere", "bob", 0.01),
}


@pytest.mark.parametrize("what", list(ADDERS))
@pytest.mark.parametrize("name", BAD)
def test_a_bad_name_is_refused_when_the_item_is_added(what, name):
    b = _pendulum()
    with pytest.raises(ModelError) as exc:
        ADDERS[what](b, name)
    message = str(exc.value)
    assert repr(name) in message and "\n" not in message
    # builder names may hold no '.' at all (qualified names are "body.frame"); that rule speaks first for '..'
    assert any(why in message for why in ("names may not contain", "contains '..'", "without '.'"))


def test_a_bad_load_and_contact_name_are_refused():
    from openfdk.contact.sections import add_contact

    b = _pendulum()
    with pytest.raises(ModelError, match=r"force element name '\.\./evil' contains '/'"):
        add_external_load(b, "../evil", "bob.origin", force=[0, 0, 1])
    with pytest.raises(ModelError, match=r"contact name '/tmp/evil' contains '/'"):
        add_contact(b, "/tmp/evil", "bob", None, "ground", None, 1e9)


def test_a_marker_label_with_a_control_character_is_refused():
    b = _pendulum()
    with pytest.raises(ModelError, match=r"marker 'tip': label 'TI\\x00P' contains '\\x00'"):
        b.add_marker("tip", "bob", [0, 0, 0], label="TI\x00P")
    b.add_marker("tip", "bob", [0, 0, 0], label="R.TIP 1")   # dots and spaces are fine in labels


def test_build_checks_names_of_items_put_in_without_the_adders():
    from openfdk.forces.elements import ExternalLoad
    from openfdk.model.timefunctions import Constant

    b = _pendulum()
    b.elements["loads"] = (ExternalLoad("a/b", 1, np.zeros(3), Constant(np.zeros(3)), Constant(np.zeros(3)),
                                        "world"),)
    with pytest.raises(ModelError, match=r"load name 'a/b' contains '/'"):
        b.build()


def test_good_names_still_build():
    b = _pendulum("bob_1-left")
    b.add_marker("tip", "bob_1-left", [0, 0, -0.1], label="TIP")
    add_spring(b, "spring.x", b.distance("ground.origin", "bob_1-left.origin"), 10.0)
    model = b.build()
    assert model.bodies[1].name == "bob_1-left"


def test_export_opensim_refuses_a_model_made_without_the_builder(tmp_path):
    from openfdk.api import run
    from openfdk.io.osim import export_opensim
    from openfdk.model.settings import AnalysisSettings

    model = _pendulum().build()
    settings = dataclasses.replace(AnalysisSettings(), kinematics={"start": 0.0, "end": 0.02, "frames": 3})
    result = run(model, settings=settings)
    bad = dataclasses.replace(model, bodies=(model.bodies[0], dataclasses.replace(model.bodies[1], name="../x")))
    out = tmp_path / "out"
    with pytest.raises(ValueError, match=r"model 'pendulum': body name '\.\./x' contains '/'"):
        export_opensim(result, out, model=bad)
    assert not out.exists()   # refused before anything is written
    assert export_opensim(result, out, model=model)["osim"].exists()
