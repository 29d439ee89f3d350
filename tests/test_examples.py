"""Every example runs as checked out or after the one documented command that generates
its inputs (``make examples``, examples/README.md), and what it generates is ignored by
git (issue 29)."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]


def _tracked_examples():
    from repo_listing import repo_files

    return repo_files("examples")


def _make_examples_commands():
    """The recipe of the Makefile's ``examples`` target, ``$(PY)`` as this Python."""
    text = (ROOT / "Makefile").read_text()
    recipe = re.search(r"^examples:.*\n((?:\t.*\n)+)", text, re.M)
    assert recipe, "the Makefile has no 'examples' target"
    return [line.strip().replace("$(PY)", sys.executable).split() for line in recipe.group(1).splitlines()]


def _model_files(root):
    return sorted(p for p in (root / "examples").rglob("*.yaml") if "bodies" in yaml.safe_load(p.read_text()))


def _study_files(root):
    return sorted(p for p in (root / "examples" / "studies").glob("*.yaml")
                  if "models" in yaml.safe_load(p.read_text()))


def _missing_study_inputs(study):
    data = yaml.safe_load(study.read_text())
    paths = list((data.get("models") or {}).values()) + list((data.get("trials") or {}).values())
    return [p for p in paths if isinstance(p, str) and not (study.parent / p).exists()]


def test_examples_run_as_checked_out_or_after_make_examples(tmp_path):
    from openfdk.io.modelfile import load_model

    copy = tmp_path / "checkout"
    for rel in _tracked_examples():
        (copy / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / rel, copy / rel)
    documented = (ROOT / "examples" / "README.md").read_text()
    ready = {"slider_crank.yaml", "knee/knee_springs.yaml", "studies/slider_crank_speed_and_mass.yaml"}
    # as checked out: the examples listed as ready load, the others name a missing file
    for path in _model_files(copy):
        rel = path.relative_to(copy / "examples").as_posix()
        if rel in ready:
            load_model(path)
        else:
            with pytest.raises((ValueError, OSError)):
                load_model(path)
            assert f"`{rel}" in documented or f"`{rel.split('/')[0]}/{Path(rel).name}`" in documented, rel
    for study in _study_files(copy):
        rel = study.relative_to(copy / "examples").as_posix()
        assert (not _missing_study_inputs(study)) == (rel in ready), rel
    # one command generates the rest
    for command in _make_examples_commands():
        subprocess.run(command, cwd=copy, check=True, capture_output=True, timeout=600)
    for path in _model_files(copy):
        load_model(path)
    for study in _study_files(copy):
        assert not _missing_study_inputs(study), study


def test_generated_example_inputs_are_ignored_by_git():
    _tracked_examples()
    generated = ["examples/knee/meshes/femoral_condyle.stl", "examples/shoulder/meshes/humeral_head.stl",
                 "examples/shoulder/reach.trc", "examples/studies/tmj/tmj_fdk.yaml",
                 "examples/studies/tmj/open_close.c3d"]
    from repo_listing import gitignore_patterns, is_ignored

    assert all(is_ignored(g, gitignore_patterns()) for g in generated)
    assert not any(is_ignored(p.as_posix(), gitignore_patterns()) for p in _tracked_examples())
    out = subprocess.run(["git", "check-ignore", "--no-index", *generated], cwd=ROOT, capture_output=True, text=True)
    if out.returncode != 128:  # in a git checkout, git agrees
        assert sorted(out.stdout.split()) == sorted(generated)
