"""The repository's own files (issue 29): a LICENSE matching pyproject.toml, the design
document the code and docs cite, and a README that says how long ``make demo`` and
``make test`` take and how to install without make."""

import re
import tomllib
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]


def _tracked_text_files():
    from repo_listing import repo_files

    return [ROOT / p for p in repo_files("*.py", "*.md", "*.yaml", "*.toml", "Makefile") if (ROOT / p).is_file()]


def test_license_is_bsd3_as_pyproject_says():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "BSD-3-Clause"
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License")
    assert "Copyright (c) 2026, the openfdk developers" in text
    assert "Neither the name of the copyright holder nor the names of its" in text


def test_design_document_is_the_repositorys_own_and_cited_sections_exist():
    design = (ROOT / "docs" / "design.md").read_text()
    sections = set(re.findall(r"^## (\d)\. ", design, re.M))
    assert sections == {"1", "2", "3", "4", "5"}
    this = Path(__file__).resolve()
    cited = 0
    for path in _tracked_text_files():
        if path.resolve() == this:
            continue
        text = path.read_text(errors="replace")
        assert "DESIGN.md" not in text, f"{path.relative_to(ROOT)} cites DESIGN.md, not docs/design.md"
        for section in re.findall(r"design\.md\)? §(\d)", text):
            assert section in sections, f"{path.relative_to(ROOT)} cites design.md §{section}"
            cited += 1
    assert cited > 40


def test_readme_durations_and_install_without_make():
    readme = (ROOT / "README.md").read_text()
    head = " ".join(readme.split("## What it does")[0].split())
    assert re.search(r"`make demo` takes about \d+ min", head)
    assert re.search(r"`make test` about \d+ min", head)
    assert "pip install -e ." in head and "### Without make" in head
    assert "[LICENSE](LICENSE)" in readme and "[design](docs/design.md)" in readme
