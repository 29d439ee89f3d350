"""Figures (matplotlib, Agg backend): the figures of any run (:mod:`.run`, ``openfdk
plot`` and the end of ``openfdk run``) and the demos' figures (:mod:`.figures`). They read
runs through :mod:`openfdk.results`."""
