"""Reading an ``openfdk run`` result folder for the viewer: through the results layer
(:mod:`openfdk.results.columns`), plus finding the run's model and trial files.

A result folder holds ``kinematics.csv`` (body poses, marker residuals), ``forces.csv``
(muscle, ligament, spring, contact and FDK columns) and ``summary.json`` whose
``input.model`` (and ``input.model_file``, absolute, since the viewer exists) names the
model file and ``input.trial`` the trial. The viewer rebuilds geometry by loading that
model file.
"""

from __future__ import annotations

from pathlib import Path

from ..results.columns import ResultsError, read_run_tables


#: a result folder cannot be viewed; the message names the file and the entry
ViewError = ResultsError
#: the run's tables, columns parsed when used (:func:`openfdk.results.columns.read_run_tables`)
read_results = read_run_tables


def _candidates(text, directory):
    p = Path(text)
    if p.is_absolute():
        yield p
        return
    yield Path.cwd() / p
    for parent in [directory, *directory.resolve().parents]:
        yield parent / p


def resolve_input(results, key, override=None):
    """Path of the run's ``key`` input ("model" or "trial"): ``override`` if given, else
    ``summary.json`` input.<key>_file (absolute) or input.<key> (as typed when the run
    was started: tried relative to the working directory, then to the result folder and
    its parents). Returns None when the summary names none; raises ViewError naming
    summary.json when it names a file that cannot be found."""
    if override is not None:
        p = Path(override)
        if not p.is_file():
            raise ViewError(f"{key} file {str(p)!r} does not exist")
        return p
    info = results.summary.get("input", {}) if isinstance(results.summary, dict) else {}
    for entry in (f"{key}_file", key):
        text = info.get(entry)
        if not isinstance(text, str) or not text:
            continue
        for p in _candidates(text, results.directory):
            if p.is_file():
                return p
    text = info.get(f"{key}_file") or info.get(key)
    if text:
        raise ViewError(f"{results.directory / 'summary.json'}: input.{key}: file {text!r} not found "
                        f"(give it with --{key})")
    return None
