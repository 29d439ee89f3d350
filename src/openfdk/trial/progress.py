"""Progress display for loops over frames, chunks or cases.

On a terminal it is a bar (tqdm) that redraws one line. When stderr is not a terminal
(a log file, a pipe, a batch job) it is one plain line per 10 % — no carriage returns,
so logs stay readable. ``set_quiet(True)`` (the CLI's ``--quiet``) turns every display
off.
``set_warmup(True)`` (the CLI, when numba's kernel cache is cold) makes each display start
after its first step — the step that compiles the kernels — so the elapsed time and the
rate count frames, not compilation.

    with progress(total=n, desc="kinematics", unit="frame", enabled=True) as bar:
        for ...:
            bar.update(1)
"""

from __future__ import annotations

import sys
import time

_QUIET = False
_WARMUP = False


def set_quiet(quiet: bool) -> None:
    """Turn every progress display off (True) or back on (False)."""
    global _QUIET
    _QUIET = bool(quiet)


def is_quiet() -> bool:
    return _QUIET


def warming_up() -> bool:
    """True while the current command runs on a cold kernel cache (:func:`set_warmup`)."""
    return _WARMUP


def set_warmup(warmup: bool) -> None:
    """True: the next displays show nothing until their first ``update`` (the first frame,
    which compiles the numba kernels on a cold cache) and start their clock after it."""
    global _WARMUP
    _WARMUP = bool(warmup)


class _Silent:
    """No display."""

    def update(self, n=1):
        pass

    def close(self):
        pass

    def set_postfix(self, **kw):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def plural(unit: str, n: int) -> str:
    """``unit`` for n == 1, else its plural: ``frame`` -> ``frames``, ``case`` -> ``cases``."""
    if n == 1 or not unit or unit.endswith("s"):
        return unit
    return unit[:-1] + "ies" if unit.endswith("y") and unit[-2:-1] not in "aeiou" else unit + "s"


class _Lines(_Silent):
    """One line per 10 % on a non-terminal stream: ``<desc>: 30% (15/50 frames, 2.1 s)``."""

    def __init__(self, total, desc, unit, stream, initial=0):
        self.total, self.desc, self.unit, self.stream = max(int(total), 0), desc, unit, stream
        self.done, self.t0 = int(initial), time.perf_counter()
        self.next_tenth = self._tenth() + 1

    def _tenth(self):
        return (10 * self.done) // self.total if self.total else 10

    def update(self, n=1):
        self.done += int(n)
        tenth = min(self._tenth(), 10)
        if tenth >= self.next_tenth:
            self.next_tenth = tenth + 1
            self.stream.write(f"{self.desc}: {10 * tenth}% ({self.done}/{self.total} {plural(self.unit, self.total)}, "
                              f"{time.perf_counter() - self.t0:.1f} s)\n")
            self.stream.flush()


class _AfterFirstStep(_Silent):
    """Silent until the first ``update(n)``; then a display made by ``make(initial)`` with
    ``initial`` = the steps done so far, whose clock starts there."""

    def __init__(self, make, initial):
        self.make, self.initial, self.shown = make, int(initial), None

    def update(self, n=1):
        if self.shown is None:
            self.shown = self.make(self.initial + int(n))
        else:
            self.shown.update(n)

    def set_postfix(self, **kw):
        if self.shown is not None:
            self.shown.set_postfix(**kw)

    def close(self):
        if self.shown is not None:
            self.shown.close()


def progress(total, desc="", unit="frame", enabled=True, initial=0, stream=None):
    """A progress display with ``update(n)`` and ``close()`` (also a context manager):
    a tqdm bar when ``stream`` (default stderr) is a terminal, one line per 10 % when it
    is not, nothing when ``enabled`` is False or the display is quiet. After
    ``set_warmup(True)`` the display appears after the first step, timed from there."""
    if not enabled or _QUIET:
        return _Silent()
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)

    def make(initial):
        if isatty is not None and isatty():
            from tqdm.auto import tqdm

            return tqdm(total=total, desc=desc, unit=unit, leave=False, initial=initial, file=stream)
        return _Lines(total, desc, unit, stream, initial)

    return _AfterFirstStep(make, initial) if _WARMUP else make(initial)
