"""The model-description error, in a module of its own so that code which only reads
model files as data (a study's driver process: parsing, overrides, case folders) can
raise and catch it without importing the model layers (numba kernels, scipy)."""


class ModelError(ValueError):
    """A model description is invalid; the message names the offending entry."""
