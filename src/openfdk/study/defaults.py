"""Defaults of study and chunked-run options (a light module: the command line imports
it to build its parser without loading the analysis layers)."""

DEFAULT_OVERLAP = 5  # frames of warm-up solved before each chunk and dropped
DEFAULT_RETRIES = 2  # further runs of a failing case

#: the sub-folder of a study's output that holds one folder per case
CASES = "cases"
