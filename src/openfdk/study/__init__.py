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

from .chunks import Segment, SegmentResult, plan_segments, solve_segment, stitch
from .cli import add_chunk_arguments, add_study_parser, run_chunked_job
from .kinds import CASE_KINDS, CaseKind, PreparedCase, register_case_kind
from .overrides import Override, OverrideError, apply_overrides, resolve
from .runner import StudyResult, run_study
from .spec import Case, Parameter, RunOptions, Study, StudyError, load_study, study_from_dict
from .summary import case_metrics, case_series, parameter_band, read_table

__all__ = [
    "CASE_KINDS", "Case", "CaseKind", "Override", "OverrideError", "Parameter", "PreparedCase", "RunOptions",
    "Segment", "SegmentResult", "Study", "StudyError", "StudyResult", "add_chunk_arguments", "add_study_parser",
    "apply_overrides", "case_metrics", "case_series", "load_study", "parameter_band", "plan_segments",
    "read_table", "register_case_kind", "resolve", "run_chunked_job", "run_study", "solve_segment", "stitch",
    "study_from_dict",
]
