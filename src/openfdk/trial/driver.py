"""The trial driver: one loop over the analysed frames for every analysis.

An analysis supplies a *step* object (its per-frame solver with its warm starts):

* ``fields()`` → ``{name: (shape, dtype, fill)}`` the per-frame values it records;
* ``step(k)`` → ``[(j, values)]`` the frames finished by processing frame k (usually
  ``[(k, …)]``; marker tracking finishes frame k − 1 once frame k's pose is known,
  because Eq. 7 needs the residuals at t ± Δt);
* ``finish()`` → the frames still pending after the last one;
* ``carry()`` / ``restore(carry)`` → its warm-start state, for checkpoints (only the
  types of :mod:`openfdk.trial.checkpoint_format`).

:func:`drive` owns the loop, the progress display, the recording (a
:class:`Recording`, frozen when the loop ends), periodic checkpoints and Ctrl-C: the
first one stops the loop after the current frame, and :class:`TrialInterrupted` carries
the result built from the frames finished so far.
"""

from __future__ import annotations

import signal
import threading

import numpy as np

from .status import NOT_RUN, FrameReport

REPORT = "report"  # conventional name of the FrameReport field of a step


class Recording:
    """Per-frame values of one trial, filled frame by frame, then frozen.

    n_frames : int; fields : {name: (shape, dtype, fill)} declared by the step; values
    of undeclared names become float arrays (NaN fill) or, for text and objects, tuples.
    """

    def __init__(self, n_frames, fields=None):
        self.n_frames = int(n_frames)
        self._arrays = {}
        self._objects = {}
        self.done = np.zeros(self.n_frames, dtype=bool)
        self.interrupted = False
        for name, (shape, dtype, fill) in (fields or {}).items():
            self._declare(name, shape, dtype, fill)

    def _declare(self, name, shape, dtype, fill):
        if dtype is object:
            self._objects[name] = [fill] * self.n_frames
        else:
            self._arrays[name] = np.full((self.n_frames, *shape), fill, dtype=dtype)

    def record(self, k, values):
        """Store frame k's values (dict name -> value) and mark it finished."""
        arrays, objects = self._arrays, self._objects
        for name, value in values.items():
            a = arrays.get(name)
            if a is not None:
                a[k] = value
                continue
            o = objects.get(name)
            if o is None:
                if isinstance(value, (str, FrameReport)) or value is None:
                    self._declare(name, (), object, None)
                else:
                    self._declare(name, np.shape(value), float, np.nan)
                    arrays[name][k] = value
                    continue
                o = objects[name]
            o[k] = value
        self.done[k] = True

    @property
    def frames_done(self):
        """Number of leading finished frames (all of them after a complete run)."""
        missing = np.flatnonzero(~self.done)
        return int(missing[0]) if missing.size else self.n_frames

    def names(self):
        return list(self._arrays) + list(self._objects)

    def __contains__(self, name):
        return name in self._arrays or name in self._objects

    def array(self, name):
        """A read-only view of a numeric field (n_frames, …)."""
        a = self._arrays[name]
        a.setflags(write=False)
        return a

    def objects(self, name):
        """A tuple of an object field's per-frame values (reports: NOT_RUN if never set)."""
        vals = self._objects[name]
        if name == REPORT or name.endswith("." + REPORT):
            return tuple(NOT_RUN if v is None else v for v in vals)
        return tuple(vals)

    def truncated(self, n):
        """A new Recording holding the first n frames."""
        out = Recording(n)
        out._arrays = {k: v[:n].copy() for k, v in self._arrays.items()}
        out._objects = {k: v[:n] for k, v in self._objects.items()}
        out.done = self.done[:n].copy()
        out.interrupted = self.interrupted
        return out


class TrialInterrupted(KeyboardInterrupt):
    """Ctrl-C during a trial. ``partial`` is the result of the frames finished before
    the interruption (built by the analysis as for a complete run, with only those
    frames), ``frames_planned`` the number of frames asked for."""

    def __init__(self, partial, frames_planned):
        super().__init__("interrupted")
        self.partial = partial
        self.frames_planned = frames_planned


def _progress(total, enabled, desc, initial=0):
    if not enabled:
        return None
    from ..progress import progress

    return progress(total, desc, "frame", initial=initial)


def drive(step, n_frames, build, *, progress=False, desc="frames", checkpoints=None, resume=False):
    """Run ``step`` over frames 0 … n_frames − 1 and return ``build(recording)``.

    checkpoints : :class:`openfdk.trial.checkpoint.Checkpoints` or None — finished
    frames and the step's warm-start state are saved as the loop goes; with ``resume``
    the loop continues after the last saved frame (the result is the same as an
    uninterrupted run's, bit for bit, because the warm starts are restored exactly);
    without ``resume`` any earlier checkpoint is removed first.
    On KeyboardInterrupt raises TrialInterrupted(build(first finished frames)).
    """
    rec = Recording(n_frames, step.fields())
    start = 0
    if checkpoints is not None and resume:
        saved = checkpoints.load()
        if saved is not None:
            for j, values in saved.records:
                rec.record(j, values)
            step.restore(saved.carry)
            start = saved.next_frame
    elif checkpoints is not None:
        checkpoints.clear()  # another run's parts must not mix with this one's
    bar = _progress(n_frames, progress, desc, initial=start)
    pending = []
    stop = _StopOnSigint()
    try:
        with stop:
            for k in range(start, n_frames):
                for j, values in step.step(k):
                    rec.record(j, values)
                    if checkpoints is not None:
                        pending.append((j, values))
                if checkpoints is not None and checkpoints.due(len(pending)):
                    checkpoints.save(pending, step.carry(), k + 1)
                    pending = []
                if bar is not None:
                    bar.update()
                if stop.requested:
                    raise KeyboardInterrupt
            for j, values in step.finish():
                rec.record(j, values)
    except KeyboardInterrupt:
        rec.interrupted = True
        raise TrialInterrupted(build(rec.truncated(rec.frames_done)), n_frames) from None
    finally:
        if bar is not None:
            bar.close()
    return build(rec)


class _StopOnSigint:
    """Within the loop, the first Ctrl-C (SIGINT) only asks to stop after the current
    frame: an exception raised in the middle of a compiled kernel call would surface as
    a SystemError, not a KeyboardInterrupt. A second Ctrl-C interrupts at once. Only in
    the main thread (signal handlers cannot be set elsewhere, e.g. in Dask workers)."""

    def __init__(self):
        self.requested = False
        self._previous = None

    def _handler(self, signum, frame):
        if self.requested:  # second Ctrl-C: the previous behaviour (KeyboardInterrupt now)
            signal.default_int_handler(signum, frame)
        self.requested = True

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, *exc):
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return False
