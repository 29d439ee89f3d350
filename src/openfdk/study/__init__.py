"""Parameter studies and long trials at scale on Dask (docs/studies.md).

* :func:`load_study` / :func:`run_study` — a study file's cases (model files or other
  case kinds × trials × parameter overrides) run as independent tasks on a LocalCluster
  or any Dask scheduler, each case publishing its own folder atomically; complete cases
  are skipped on a rerun, failing cases retried then recorded.
* :func:`apply_overrides` — parameter overrides addressed by dotted path with globs.
* :func:`plan_segments` / :func:`stitch` / :func:`run_chunked_job` — one long trial in K
  frame segments solved in parallel.
* :func:`parameter_band` / :func:`case_series` — aggregation over cases for figures.
"""

import importlib

_EXPORTS = {
    "chunks": ("Segment", "SegmentResult", "plan_segments", "solve_segment", "stitch"),
    "cli": ("add_chunk_arguments", "add_study_parser", "run_chunked_job"),
    "kinds": ("CASE_KINDS", "CaseKind", "PreparedCase", "register_case_kind"),
    "overrides": ("Override", "OverrideError", "apply_overrides", "resolve"),
    "runner": ("StudyResult", "run_study"),
    "spec": ("Case", "Parameter", "RunOptions", "Study", "StudyError", "load_study", "study_from_dict"),
    "summary": ("case_metrics", "case_series", "parameter_band", "read_table"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = [
    "CASE_KINDS", "Case", "CaseKind", "Override", "OverrideError", "Parameter", "PreparedCase", "RunOptions",
    "Segment", "SegmentResult", "Study", "StudyError", "StudyResult", "add_chunk_arguments",
    "add_study_parser", "apply_overrides", "case_metrics", "case_series", "load_study", "parameter_band",
    "plan_segments", "read_table", "register_case_kind", "resolve", "run_chunked_job", "run_study",
    "solve_segment", "stitch", "study_from_dict",
]


def __getattr__(name):
    # imported on first use, so that ``openfdk.study.cli`` (the command-line parser)
    # loads without the analysis layers
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'openfdk.study' has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{module}"), name)
