"""Defaults of study and chunked-run options (a light module: the command line imports
it to build its parser without loading the analysis layers)."""

DEFAULT_OVERLAP = 5  # frames of warm-up solved before each chunk and dropped
DEFAULT_RETRIES = 2  # further runs of a failing case
