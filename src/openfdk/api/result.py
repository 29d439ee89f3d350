"""What :func:`openfdk.run` and :func:`openfdk.read_results` return: the results layer's
:class:`~openfdk.results.run.RunResults` (tables, summary, model, ``save``) with the run's
figures (``.plot()``) and 3D viewer (``.view()``). The results layer itself draws nothing,
so that the figures and the viewer read runs through it without an import cycle."""

from __future__ import annotations

from pathlib import Path

from ..results.run import RunResults

__all__ = ["Result"]


class Result(RunResults):
    """A run's results with ``.plot()`` and ``.view()`` (docs/python-api.md)."""

    # ------------------------------------------------------------------ outputs
    def plot(self, directory=None, measures=None):
        """The run's figures (:func:`openfdk.plots.run.make_figures`): a dict name ->
        matplotlib Figure. With ``directory``, also written there as PNG files."""
        from ..plots.run import make_figures, save_figures

        figures = make_figures(self, measures=measures)
        if directory is not None:
            save_figures(figures, directory)
        return figures

    def view(self, out_html=None):
        """Write the 3D viewer of this run (``openfdk view``) and return its path. An
        unsaved run is first saved to a temporary folder."""
        try:
            from ..viewer import write_view
        except ImportError as exc:
            raise ImportError("the 3D viewer (openfdk.viewer) is not installed in this openfdk; "
                              f"update openfdk to use .view() ({exc})") from None
        if self.directory is None:
            import tempfile

            self.save(tempfile.mkdtemp(prefix="openfdk-run-"))
        out_html = Path(out_html) if out_html else self.directory / "view.html"
        write_view(self.directory, out_html, model=self._model)
        return out_html
