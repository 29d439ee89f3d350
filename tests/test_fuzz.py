"""Fuzz suite, quick version (issue 16): mutated model, subject and study files, C3D and
TRC trials, OpenSim models and IK setup files either load or raise the loader's
documented error naming the file — never anything else. The long run (>= 10 000 inputs per kind) is
``python -m openfdk.bench.fuzz_inputs 10000``; its counts are in the closing note."""

import warnings

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from openfdk.bench.fuzz_inputs import (KINDS, Bases, _load, _paths, documented_error, fuzz, mutate_bytes, mutate_xml,
                                       mutate_yaml)


@pytest.fixture(scope="module")
def bases():
    b = Bases(KINDS)
    yield b
    b.close()


def _outcome(kind, bases):
    """'loaded' or 'refused'; any other exception propagates and fails the test."""
    error = documented_error(kind)
    path = bases.paths[kind]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with np.errstate(all="ignore"):
                _load(kind, path)
        return "loaded"
    except error as exc:
        assert path.name in str(exc) or path.parent.name in str(exc), str(exc)
        return "refused"


@pytest.mark.parametrize("kind", KINDS)
def test_seeded_fuzz_quick(kind, bases):
    c = fuzz(kind, 40 if kind != "subject" else 25, seed=2024, bases=bases)
    assert c["unexpected"] == []
    # both outcomes occur: the mutations are neither all harmless nor all fatal
    assert c["loaded"] > 0 and c["refused"] > 0
    assert c["loaded"] + c["refused"] == c["inputs"]


_SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.mark.parametrize("kind", ["model", "study", "subject"])
@_SETTINGS
@given(seed=st.integers(0, 2**63 - 1))
def test_hypothesis_mutated_yaml(kind, bases, seed):
    path = bases.paths[kind]
    original = path.read_bytes() if path.exists() else None
    try:
        path.write_text(mutate_yaml(bases.texts[kind], np.random.default_rng(seed)))
        _outcome(kind, bases)
    finally:
        if original is not None:
            path.write_bytes(original)


@_SETTINGS
@given(seed=st.integers(0, 2**63 - 1))
def test_hypothesis_mutated_c3d(bases, seed):
    path = bases.paths["c3d"]
    try:
        path.write_bytes(mutate_bytes(bases.c3d_bytes, np.random.default_rng(seed)))
        _outcome("c3d", bases)
    finally:
        path.write_bytes(bases.c3d_bytes)


@pytest.mark.parametrize("kind", ["osim", "ik"])
@_SETTINGS
@given(seed=st.integers(0, 2**63 - 1))
def test_hypothesis_mutated_opensim_xml(kind, bases, seed):
    """Mutated OpenSim models and IK setup files (numbers, elements, names, text)."""
    path = bases.paths[kind]
    try:
        path.write_text(mutate_xml(bases.texts[kind], np.random.default_rng(seed)))
        _outcome(kind, bases)
    finally:
        path.write_text(bases.texts[kind])


_ANY = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=6),
                 st.lists(st.floats(), max_size=4), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


@_SETTINGS
@given(data=st.data())
def test_hypothesis_any_value_at_any_entry_of_a_model(bases, data):
    """Any YAML value (of any type and magnitude, NaN and infinities included) at any
    entry of a valid model file."""
    tree = yaml.safe_load(bases.texts["model"])
    paths = [p for p, _ in _paths(tree) if p]
    path = data.draw(st.sampled_from(paths))
    node = tree
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = data.draw(_ANY)
    target = bases.paths["model"]
    try:
        target.write_text(yaml.safe_dump(tree, sort_keys=False))
        _outcome("model", bases)
    finally:
        target.write_text(bases.texts["model"])


def test_c3d_numeric_parameter_stored_as_text_is_refused_not_a_crash(tmp_path):
    """Found by the fuzz suite: FORCE_PLATFORM:CHANNEL turned into a character parameter
    made ezc3d dereference a null pointer (segmentation fault). It is now a C3DError.
    Run in a child process so that a regression fails this test instead of the session."""
    import subprocess
    import sys

    from openfdk.io.c3d import write_c3d
    from openfdk.fixtures.synthetic import synthetic_markers

    _, labels, x, _ = synthetic_markers(10)
    write_c3d(tmp_path / "ok.c3d", labels, x, 100.0)
    data = bytearray((tmp_path / "ok.c3d").read_bytes())
    i = data.index(b"CHANNEL")
    assert data[i + 9] == 2                      # type byte after the name and the 2-byte offset: int16
    data[i + 9], data[i + 10] = 255, 0           # -1: characters, 0 dimensions
    (tmp_path / "bad.c3d").write_bytes(bytes(data))
    code = ("from openfdk.io.c3d import read_c3d, C3DError\n"
            "try:\n    read_c3d(r'%s')\nexcept C3DError as e:\n    print(e)\n" % (tmp_path / "bad.c3d"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "bad.c3d: parameter FORCE_PLATFORM:CHANNEL must hold numbers" in proc.stdout


def test_trc_header_counts_nan_or_infinite_are_refused(bases, tmp_path):
    """Found by the fuzz suite: NumMarkers / NumFrames of NaN or inf raised ValueError /
    OverflowError from int(); now TRCError naming the file, the line and the field."""
    from openfdk.io.trc import TRCError, read_trc

    lines = bases.texts["trc"].split("\n")
    for field, value in ((3, "NaN"), (2, "inf"), (3, "2.5")):   # NumMarkers, NumFrames, NumMarkers
        cells = lines[2].split("\t")
        cells[field] = value
        path = tmp_path / "h.trc"
        path.write_text("\n".join(lines[:2] + ["\t".join(cells)] + lines[3:]))
        name = ("NumFrames", "NumMarkers")[field == 3]
        with pytest.raises(TRCError, match=rf"h\.trc: line 3: {name} is '{value}', expected a whole number"):
            read_trc(path)
