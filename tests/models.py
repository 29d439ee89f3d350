"""Small reference models shared by the tests (built with the public builder API)."""

import numpy as np

from openfdk.model.builder import ModelBuilder
from openfdk.model.timefunctions import Polynomial


def slider_crank(a=0.1, L=0.3, omega=2 * np.pi):
    """Planar slider–crank in the xy-plane: crank of length a about the ground origin
    (revolute about z, driven θ = ωt), rod of length L, slider on the x axis.
    Reference pose at θ = 0 (all bodies on the x axis)."""
    b = ModelBuilder("slider-crank", gravity=(0, -9.81, 0))
    b.add_body("crank", 1.0, [1e-4, 1e-3, 1e-3], position=[a / 2, 0, 0])
    b.add_frame("crank", "pivot", [-a / 2, 0, 0])
    b.add_frame("crank", "tip", [a / 2, 0, 0])
    b.add_body("rod", 2.0, [1e-4, 2e-2, 2e-2], position=[a + L / 2, 0, 0])
    b.add_frame("rod", "big_end", [-L / 2, 0, 0])
    b.add_frame("rod", "small_end", [L / 2, 0, 0])
    b.add_body("slider", 0.5, [1e-4, 1e-4, 1e-4], position=[a + L, 0, 0])
    b.add_frame("ground", "rail", [0, 0, 0], orientation=[[0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    b.add_frame("slider", "rail", [0, 0, 0], orientation=[[0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    b.add_joint("crank_pin", "revolute", parent="ground.origin", child="crank.pivot")
    b.add_driver("crank_drive", b.angles("ground.origin", "crank.origin"), Polynomial([[0.0], [omega]]), components=[2])
    b.add_joint("big_end", "revolute", parent="crank.tip", child="rod.big_end")
    b.add_joint("rail", "prismatic", parent="ground.rail", child="slider.rail")
    b.add_constraint("small_end", b.vector("slider.origin", "rod.small_end"), components=[0, 1])
    return b.build()


def slider_crank_closed_form(t, a=0.1, L=0.3, omega=2 * np.pi):
    """Slider position, velocity, acceleration (m, m/s, m/s²) and rod angle φ (rad):
    x = a cos θ + S, S = sqrt(L² − a² sin² θ), θ = ωt;
    ẋ = −a ω s − a² ω s c / S;
    ẍ = −a ω² c − a² ω² [(c² − s²)/S + a² s² c² / S³];  sin φ = −a sin θ / L."""
    th = omega * t
    s, c = np.sin(th), np.cos(th)
    S = np.sqrt(L**2 - a**2 * s**2)
    x = a * c + S
    xd = -a * omega * s - a**2 * omega * s * c / S
    xdd = -a * omega**2 * c - a**2 * omega**2 * ((c**2 - s**2) / S + a**2 * s**2 * c**2 / S**3)
    phi = np.arcsin(-a * s / L)
    return x, xd, xdd, phi


def write_jaw_files(directory, n_frames, seed=3):
    """The TMJ-like FDK jaw (tmj.yaml with its meshes), the POP jaw (pop.yaml) and a
    marker trial (trial.c3d, n_frames at 100 Hz, 0.1 mm noise) in ``directory``."""
    import yaml

    from openfdk.fixtures.synthetic_jaw import jaw_fdk_model_dict, jaw_markers, jaw_model_dict, write_jaw_meshes
    from openfdk.io.c3d import write_c3d

    write_jaw_meshes(directory / "meshes")
    (directory / "tmj.yaml").write_text(yaml.safe_dump(jaw_fdk_model_dict("meshes"), sort_keys=False))
    (directory / "pop.yaml").write_text(yaml.safe_dump(jaw_model_dict(), sort_keys=False))
    _t, labels, x, _ = jaw_markers(n_frames, noise=1e-4, seed=seed)
    write_c3d(directory / "trial.c3d", labels, x, 100.0)
    return directory


def q_difference_along(forces, state, u, step=1e-6):
    """dQ/dε (n,) [N, N m per unit ε] of ``forces`` (ForceElements) at ``state`` along the
    direction u (n,) [m, rad]: central differences of the generalised forces with the
    largest coordinate change ``step`` (an independent check of K u)."""
    h = step / np.abs(u).max()
    plus, minus = state.copy(), state.copy()
    plus.displace(h * u)
    minus.displace(-h * u)
    return (forces.generalized_forces(plus, 0.0)[0] - forces.generalized_forces(minus, 0.0)[0]) / (2 * h)
