"""Cold numba cache: detected from the kernels' index files, announced once, not counted
against frame 1 by the progress display."""

import importlib
import io
import os
import sys
import textwrap
import time
from pathlib import Path

import numba
import pytest

from openfdk.analysis import kernel_cache
from openfdk.trial import progress

KERNEL_SOURCE = """
import numba


@numba.njit(cache=True)
def double(x):
    return {factor} * x


@numba.njit(cache=True)
def square(x):
    return x * x


def not_a_kernel(x):
    return x
"""


def _import_fresh(folder, name):
    sys.modules.pop(name, None)
    importlib.invalidate_caches()
    return importlib.import_module(name)


@pytest.fixture
def kernel_module(tmp_path, monkeypatch):
    """A throw-away module of two cached kernels; numba caches them in tmp_path/__pycache__."""
    name = f"fake_kernels_{os.getpid()}_{time.monotonic_ns()}"
    src = tmp_path / f"{name}.py"
    src.write_text(textwrap.dedent(KERNEL_SOURCE.format(factor=2)))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield src, name
    sys.modules.pop(name, None)


def test_cold_then_warm_then_stale_after_source_change(kernel_module):
    src, name = kernel_module
    mod = _import_fresh(src.parent, name)
    assert kernel_cache.cold_fraction([mod]) == (2, 2)  # nothing compiled: no index files
    assert kernel_cache.cache_is_cold([mod])
    assert mod.double(3.0) == 6.0  # compiles and writes double's index
    assert kernel_cache.cold_fraction([mod]) == (1, 2)
    assert kernel_cache.cache_is_cold([mod])  # half of them cold still counts as cold
    assert mod.square(3.0) == 9.0
    assert kernel_cache.cold_fraction([mod]) == (0, 2)
    assert not kernel_cache.cache_is_cold([mod])
    # numba's index files: beside the source, or under NUMBA_CACHE_DIR when that is set
    where = Path(numba.config.CACHE_DIR) if numba.config.CACHE_DIR else src.parent / "__pycache__"
    assert any(p.suffix == ".nbi" and name in p.name for p in where.rglob("*.nbi"))
    # an upgrade rewrites the source: new stamp (size and mtime), the index is stale
    src.write_text(textwrap.dedent(KERNEL_SOURCE.format(factor=20)))
    os.utime(src, (time.time() + 5, time.time() + 5))
    mod = _import_fresh(src.parent, name)
    assert kernel_cache.cold_fraction([mod]) == (2, 2)
    assert mod.double(3.0) == 60.0


def test_a_module_never_compiled_makes_the_cache_cold(tmp_path, monkeypatch):
    """`openfdk check` warms the constraint program only; the run's other modules are still
    cold: one module with no compiled kernel is enough, however warm the others."""
    names = []
    for i in range(3):
        name = f"fake_kernels_{os.getpid()}_{time.monotonic_ns()}_{i}"
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(KERNEL_SOURCE.format(factor=2)))
        names.append(name)
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        mods = [_import_fresh(tmp_path, n) for n in names]
        for m in mods[:2]:
            m.double(1.0), m.square(1.0)
        assert kernel_cache.cold_fraction(mods) == (2, 6)  # a third cold: under half
        assert kernel_cache.cache_is_cold(mods)  # but mods[2] has nothing compiled
        mods[2].double(1.0)
        assert not kernel_cache.cache_is_cold(mods)
    finally:
        for n in names:
            sys.modules.pop(n, None)


def test_announce_prints_one_line_unless_quiet(kernel_module, monkeypatch):
    src, name = kernel_module
    mod = _import_fresh(src.parent, name)
    try:
        out = io.StringIO()
        assert kernel_cache.announce_cold_cache(stream=out, modules=[mod])
        assert progress._WARMUP
        assert out.getvalue() == kernel_cache.MESSAGE + "\n"
        assert "compiling numerical kernels" in out.getvalue()
        out = io.StringIO()
        assert kernel_cache.announce_cold_cache(quiet=True, stream=out, modules=[mod])
        assert out.getvalue() == ""
        mod.double(1.0), mod.square(1.0)
        out = io.StringIO()
        assert not kernel_cache.announce_cold_cache(stream=out, modules=[mod])
        assert not progress._WARMUP
        assert out.getvalue() == ""
    finally:
        progress.set_warmup(False)


def test_progress_clock_starts_after_the_first_step():
    """With a cold cache the first frame's compile time is not counted: the display appears
    after step 1 and its elapsed time covers steps 2… only."""
    out = io.StringIO()
    progress.set_warmup(True)
    try:
        bar = progress.progress(10, "fdk", "frame", stream=out)
        time.sleep(0.3)  # the compiling first frame
        bar.update(1)
        assert out.getvalue() == ""  # the first 10 % is the compiling frame: no line for it
        for _ in range(9):
            bar.update(1)
        bar.close()
    finally:
        progress.set_warmup(False)
    last = out.getvalue().splitlines()[-1]
    assert last.startswith("fdk: 100% (10/10 frames, ")
    assert float(last.split(", ")[1].split()[0]) < 0.3
    # warm cache: the clock starts at creation, as before
    out = io.StringIO()
    bar = progress.progress(10, "fdk", "frame", stream=out)
    time.sleep(0.3)
    bar.update(10)
    assert float(out.getvalue().split(", ")[1].split()[0]) >= 0.3


def test_openfdk_kernels_are_found():
    """The frame-kernel modules hold cached kernels (a renamed module would make the check blind)."""
    n_cold, n_total = kernel_cache.cold_fraction()
    assert n_total >= 20 and 0 <= n_cold <= n_total


@pytest.mark.parametrize("quiet", [False, True])
def test_check_announces_a_cold_cache_once(tmp_path, capsys, monkeypatch, quiet):
    """openfdk check on a valid model: the line on stderr exactly once (cold), none with --quiet."""
    import yaml

    from openfdk.cli import main
    from openfdk.fixtures.synthetic import two_body_model_dict

    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(two_body_model_dict(), sort_keys=False))
    monkeypatch.setattr(kernel_cache, "cache_is_cold", lambda modules: True)
    code = main(["check", str(path)] + (["--quiet"] if quiet else []))
    err = capsys.readouterr().err
    assert code == 0
    assert err.count(kernel_cache.MESSAGE) == (0 if quiet else 1)
    assert not progress._WARMUP  # reset when the command ends


def test_analysis_announces_after_reading_the_trial(tmp_path, capsys, monkeypatch):
    """openfdk kinematics with a bad trial file: the one-line error only (the announcement
    waits until model and trial are read); with a good one: the line, once."""
    import yaml

    from openfdk.cli import main
    from openfdk.fixtures.synthetic import synthetic_markers, two_body_model_dict
    from openfdk.io.c3d import write_c3d

    monkeypatch.setattr(kernel_cache, "cache_is_cold", lambda modules: True)
    model = tmp_path / "m.yaml"
    model.write_text(yaml.safe_dump(two_body_model_dict(), sort_keys=False))
    bad = tmp_path / "bad.trc"
    bad.write_text("Something else\n" * 6)
    assert main(["kinematics", str(model), str(bad), "--out", str(tmp_path / "o1"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "bad.trc" in err and kernel_cache.MESSAGE not in err
    t, labels, x, _ = synthetic_markers(n_frames=20)
    good = tmp_path / "good.c3d"
    write_c3d(good, labels, x, 100.0, units="mm")
    assert main(["kinematics", str(model), str(good), "--out", str(tmp_path / "o2"), "--no-progress"]) == 0
    assert capsys.readouterr().err.count(kernel_cache.MESSAGE) == 1
    assert kernel_cache._ARMED is None and not progress._WARMUP


def _two_body_files(tmp_path):
    """The two-body model file m.yaml and a 20-frame marker trial t.c3d of it in
    ``tmp_path``; returns the model's path."""
    import yaml

    from openfdk.fixtures.synthetic import synthetic_markers, two_body_model_dict
    from openfdk.io.c3d import write_c3d

    model = tmp_path / "m.yaml"
    model.write_text(yaml.safe_dump(two_body_model_dict(), sort_keys=False))
    t, labels, x, _ = synthetic_markers(n_frames=20)
    write_c3d(tmp_path / "t.c3d", labels, x, 100.0, units="mm")
    return model


@pytest.mark.parametrize("cold", [True, False])
def test_frame_rate_line_says_when_it_includes_compilation(tmp_path, capsys, monkeypatch, cold):
    """The frames/s figure of a command that found the kernel cache cold includes the
    compilation; the line says so (and only then)."""
    from openfdk.cli import main

    monkeypatch.setattr(kernel_cache, "cache_is_cold", lambda modules: cold)
    model = _two_body_files(tmp_path)
    assert main(["kinematics", str(model), str(tmp_path / "t.c3d"), "--out", str(tmp_path / "o"),
                 "--no-progress"]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("kinematics:"))
    assert "frames/s" in line
    assert ("including the kernels' first compilation" in line) is cold


def test_kinematics_asks_only_for_the_kernels_it_calls(tmp_path, monkeypatch):
    """openfdk kinematics never calls the recruitment's kernels: counting them (they stay
    uncompiled after an install or an upgrade until a run with dynamics) made every
    kinematics command say it was compiling, and its frames/s line say it included the
    compilation, on a warm cache. It asks for the constraint program's and the frame
    solve's modules; openfdk run for the recruitment's too."""
    from openfdk.cli import main

    asked = []
    monkeypatch.setattr(kernel_cache, "cache_is_cold", lambda modules: asked.append(tuple(modules)) or False)
    model = _two_body_files(tmp_path)
    assert main(["kinematics", str(model), str(tmp_path / "t.c3d"), "--out", str(tmp_path / "k"),
                 "--no-progress"]) == 0
    assert asked == [kernel_cache.KINEMATICS_KERNEL_MODULES]
    assert not any(m.startswith("openfdk.recruitment") for m in asked[0])
    for module in asked[0]:  # each holds cached kernels (a renamed module would blind the check)
        assert kernel_cache.cached_dispatchers(importlib.import_module(module))
    asked.clear()
    main(["run", str(model), str(tmp_path / "t.c3d"), "--out", str(tmp_path / "r"), "--no-progress"])
    assert asked == [kernel_cache.FRAME_KERNEL_MODULES]  # (whatever the run's frames do)


@pytest.mark.parametrize("quiet", [False, True])
def test_a_long_compilation_while_the_inputs_are_read_is_announced_then(monkeypatch, quiet):
    """Found on DM at a cold cache: its model's own kernels (contacts, paths, grids)
    compiled for about 2 min while the model was built, in silence, before the
    announcement after the inputs. A compilation while armed that lasts ANNOUNCE_AFTER_S
    prints the line then, once: the announcement after the inputs does not repeat it."""
    import io
    import threading

    import numba

    stream = io.StringIO()
    monkeypatch.setattr(kernel_cache.sys, "stderr", stream)
    monkeypatch.setattr(kernel_cache, "ANNOUNCE_AFTER_S", 0.0)
    monkeypatch.setattr(kernel_cache, "cache_is_cold", lambda modules: True)
    kernel_cache.arm(quiet=quiet)
    try:
        @numba.njit(cache=False)
        def fresh(x):  # a new function: numba compiles it at the first call
            return x * 2.0 + 1.0

        assert fresh(1.5) == 4.0
        watch = kernel_cache._WATCH
        assert watch is not None and (watch.timer is None) == quiet
        if watch.timer is not None:
            watch.timer.join(5.0)
        assert stream.getvalue().count(kernel_cache.MESSAGE) == (0 if quiet else 1)
        kernel_cache.announce_armed()
        assert stream.getvalue().count(kernel_cache.MESSAGE) == (0 if quiet else 1)
        assert kernel_cache._WATCH is None  # the watch ends with the inputs read
        assert all(t.daemon for t in threading.enumerate() if isinstance(t, threading.Timer))
    finally:
        kernel_cache.disarm()


def test_no_announcement_without_a_compilation(monkeypatch):
    """Armed, with every kernel loaded from the cache (no numba:compile event), nothing is
    printed until the announcement after the inputs asks whether the cache is cold."""
    import io

    stream = io.StringIO()
    monkeypatch.setattr(kernel_cache.sys, "stderr", stream)
    monkeypatch.setattr(kernel_cache, "ANNOUNCE_AFTER_S", 0.0)
    kernel_cache.arm()
    try:
        assert kernel_cache._WATCH is not None and kernel_cache._WATCH.timer is None
        assert stream.getvalue() == ""
    finally:
        kernel_cache.disarm()


def test_check_announces_a_compilation_while_the_model_is_read(tmp_path, capsys, monkeypatch):
    """Found walking the knee tutorial on a fresh clone: after ``make demo`` the check's own
    kernels were cached, but DM's model compiled its contact and path kernels for 69 s
    while ``openfdk check dm.yaml`` read it, in silence (check announced only after the
    model was read, and only for the check's kernels). A compilation while check reads the
    model now prints the line, once, although the check's kernels are warm."""
    import numba
    import yaml

    from openfdk.cli import main
    from openfdk.fixtures.synthetic import two_body_model_dict
    from openfdk.io import modelfile

    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(two_body_model_dict(), sort_keys=False))
    monkeypatch.setattr(kernel_cache, "ANNOUNCE_AFTER_S", 0.0)
    monkeypatch.setattr(kernel_cache, "cache_is_cold", lambda modules: False)
    read = modelfile.load_model

    def compiling_read(*args, **kwargs):
        @numba.njit(cache=False)
        def fresh(x):  # a new function: numba compiles it at the first call
            return 3.0 * x

        assert fresh(2.0) == 6.0
        if kernel_cache._WATCH is not None and kernel_cache._WATCH.timer is not None:
            kernel_cache._WATCH.timer.join(5.0)
        return read(*args, **kwargs)

    monkeypatch.setattr(modelfile, "load_model", compiling_read)
    code = main(["check", str(path)])
    err = capsys.readouterr().err
    assert code == 0, err
    assert err.count(kernel_cache.MESSAGE) == 1
    monkeypatch.setattr(modelfile, "load_model", read)
    code = main(["check", str(path)])  # no compilation, warm cache: no line
    assert code == 0 and kernel_cache.MESSAGE not in capsys.readouterr().err
