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

import enum
import signal
import threading

import numpy as np

from ..model.state import BodyStates, pose_error
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

    def record_block(self, start, values):
        """Store frames start … start + n − 1 at once (a trial solved in one compiled
        call): values {declared name: (n, …) array, or a sequence of n objects for an
        object field}; marks them finished."""
        n = 0
        for name, value in values.items():
            n = len(value)
            if name in self._arrays:
                self._arrays[name][start : start + n] = value
            elif name in self._objects:
                self._objects[name][start : start + n] = list(value)
            else:
                raise KeyError(f"field {name!r} is not declared")
        self.done[start : start + n] = True

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


def _attributes(obj):
    return getattr(type(obj), "__dataclass_fields__", None) or getattr(type(obj), "__slots__", ())


def _examples(template, out=None):
    """{class: an instance} of the openfdk objects found in ``template``."""
    out = {} if out is None else out
    if isinstance(template, (tuple, list)):
        for v in template:
            _examples(v, out)
    elif isinstance(template, dict):
        for v in template.values():
            _examples(v, out)
    elif _attributes(template) and not isinstance(template, np.ndarray):
        out.setdefault(type(template), template)
    return out


def _plain(value, examples, depth=0):
    """Whether ``value`` (in a slot the fresh state leaves None) is plain data: None,
    a bool, a number, text or an enum member, a numeric array of at least one dimension
    (NaN marks missing values), containers of these, or an openfdk object whose fields
    are (one of a class the state holds must fit that instance)."""
    if depth > 20:
        return False
    if value is None or isinstance(value, (bool, str, int, float, np.number, enum.Enum)):
        return True
    if isinstance(value, np.ndarray):
        return value.ndim >= 1 and (value.dtype == bool or np.issubdtype(value.dtype, np.number))
    if isinstance(value, (tuple, list)):
        return all(_plain(v, examples, depth + 1) for v in value)
    if isinstance(value, dict):
        return all(isinstance(k, (int, str)) and _plain(v, examples, depth + 1) for k, v in value.items())
    if type(value) in examples:
        return _fits(value, examples[type(value)], examples)
    names = _attributes(value)
    return bool(names) and all(_plain(getattr(value, a, None), examples, depth + 1) for a in names)


def _fits(value, template, examples):
    """Whether a value read from a checkpoint has the structure of ``template``, the
    step's own warm-start state: the same types, arrays of the same dtype and shape,
    tuples of the same length, the same fields for openfdk's classes (a BodyStates also
    the same bodies and columns: the model's structure); where the template holds None
    (state not yet set) or an empty container, plain data (:func:`_plain`)."""
    if template is None:
        return _plain(value, examples)
    if isinstance(template, np.ndarray):
        return isinstance(value, np.ndarray) and value.dtype == template.dtype and value.shape == template.shape
    if type(value) is not type(template):
        return isinstance(template, (int, float)) and not isinstance(template, bool) \
            and isinstance(value, (int, float, np.number)) and not isinstance(value, bool)
    if isinstance(template, tuple):
        return len(value) == len(template) and all(_fits(v, t, examples) for v, t in zip(value, template))
    if isinstance(template, list):
        return all(_fits(v, template[0], examples) if template else _plain(v, examples) for v in value)
    if isinstance(template, dict):
        first = next(iter(template.values()), None)
        return all(_fits(v, first, examples) if template else _plain(v, examples) for v in value.values())
    if isinstance(template, BodyStates) and not (
            np.array_equal(value.column, template.column) and np.array_equal(value.moving, template.moving)
            and value.n_coords == template.n_coords):
        return False  # the model's structure, not state: which q̂ columns the compiled kernels index
    return all(_fits(getattr(value, a, None), getattr(template, a, None), examples) for a in _attributes(template))


def _restore_saved(saved, rec, step, folder):
    """Put a checkpoint's finished frames into ``rec`` and its warm-start state into
    ``step``; returns the frame to continue from. Parts that do not fit this run (frame
    indices outside the trial, values of other shapes or types than the step records, a
    state of another structure) are a CheckpointError naming the checkpoint folder."""
    from .checkpoint import CheckpointError

    def refuse(what):
        return CheckpointError(f"{folder}: the checkpoint does not fit this run ({what}); start again with --force")

    n = rec.n_frames
    if isinstance(saved.next_frame, bool) or not 0 <= saved.next_frame <= n:
        raise refuse(f"next frame {saved.next_frame} of {n}")
    fields = step.fields()
    for j, values in saved.records:
        if isinstance(j, bool) or not 0 <= j < n:
            raise refuse(f"frame {j} of {n}")
        for name, value in values.items():
            if not isinstance(name, str):
                raise refuse(f"frame {j}: a value named {name!r}")
            shape, dtype, _ = fields.get(name, (None, None, None))
            if dtype is object or (shape is None and (isinstance(value, (str, FrameReport)) or value is None)):
                if not (isinstance(value, (str, FrameReport)) or value is None):
                    raise refuse(f"frame {j}: {str(name)[:60]!r} is a {type(value).__name__}")
                if isinstance(value, FrameReport) and not value.well_typed():
                    raise refuse(f"frame {j}: {str(name)[:60]!r} is a frame report with fields of other types")
            elif not isinstance(value, (int, float, np.number, np.ndarray)) or isinstance(value, bool) \
                    or (shape is not None and np.shape(value) != tuple(shape)) \
                    or not np.issubdtype(np.asarray(value).dtype, np.number):
                raise refuse(f"frame {j}: {str(name)[:60]!r} is not {'a number' if not shape else f'an array {shape}'}")
            elif name == "kin.q" and pose_error(value):
                raise refuse(f"frame {j}: 'kin.q': {pose_error(value)}")
    template = step.carry()
    if not _fits(saved.carry, template, _examples(template)):
        raise refuse("the solver state has another structure")
    try:
        for j, values in saved.records:
            rec.record(j, values)
        step.restore(saved.carry)
    except (ValueError, TypeError, IndexError, KeyError, AttributeError) as exc:
        raise refuse(f"{type(exc).__name__}: {' '.join(str(exc).split())[:120]}") from None
    return saved.next_frame


def _resumed_call(call, k, folder):
    """``call(k)`` (or ``call()``) on the first frames after a resume, whose warm starts
    come from the checkpoint: an exception there is a CheckpointError naming the folder
    (the state restored from the parts is what differs from a fresh run)."""
    from .checkpoint import CheckpointError

    try:
        return list(call() if k is None else call(k))
    except Exception as exc:  # noqa: BLE001 - the restored state is untrusted input
        at = "the last frames" if k is None else f"frame {k}"
        raise CheckpointError(f"{folder}: resuming from the checkpoint failed at {at} ({type(exc).__name__}: "
                              f"{' '.join(str(exc).split())[:120]}); start again with --force") from None


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
    from .progress import progress

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
    start, resumed = 0, None
    if checkpoints is not None and resume:
        saved = checkpoints.load()
        if saved is not None:
            start = resumed = _restore_saved(saved, rec, step, checkpoints.folder)
    elif checkpoints is not None:
        checkpoints.clear()  # another run's parts must not mix with this one's
    bar = _progress(n_frames, progress, desc, initial=start)
    pending = []
    stop = _StopOnSigint()
    try:
        with stop:
            for k in range(start, n_frames):
                near = resumed is not None and k < resumed + 2
                for j, values in (_resumed_call(step.step, k, checkpoints.folder) if near else step.step(k)):
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
            near = resumed is not None and n_frames < resumed + 2
            for j, values in (_resumed_call(step.finish, None, checkpoints.folder) if near else step.finish()):
                rec.record(j, values)
    except (KeyboardInterrupt, SystemError) as exc:
        if not caused_by_interrupt(exc):
            raise
        rec.interrupted = True
        raise TrialInterrupted(build(rec.truncated(rec.frames_done)), n_frames) from None
    finally:
        if bar is not None:
            bar.close()
    return build(rec)


def caused_by_interrupt(exc):
    """Whether ``exc`` (a SystemError) was caused by a KeyboardInterrupt: the second
    Ctrl-C raised inside a compiled kernel surfaces as a chain of SystemErrors."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


class _StopOnSigint:
    """Within the loop, the first Ctrl-C (SIGINT) or SIGTERM (what a batch system or
    ``timeout`` sends) only asks to stop after the current frame: an exception raised in
    the middle of a compiled kernel call would surface as a SystemError, not a
    KeyboardInterrupt; the finished frames are then written, marked partial. A second
    signal interrupts at once. Only in the main thread (signal handlers cannot be set
    elsewhere, e.g. in Dask workers)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.requested = False
        self._previous = {}

    def _handler(self, signum, frame):
        if self.requested:  # a second signal: KeyboardInterrupt now
            signal.default_int_handler(signum, frame)
        self.requested = True

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            self._previous = {sig: signal.signal(sig, self._handler) for sig in self.SIGNALS}
        return self

    def __exit__(self, *exc):
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        return False
