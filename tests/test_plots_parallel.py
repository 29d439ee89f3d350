"""A run's figures drawn in worker processes (openfdk.plots.parallel) against the same
figures drawn in this process."""

import itertools
import multiprocessing
import os

import numpy as np
import pytest
import yaml

from openfdk.cli.commands import main
from openfdk.fixtures.synthetic import synthetic_markers, two_body_model_dict
from openfdk.io.c3d import write_c3d
from openfdk.io.outdir import OutputDirError
from openfdk.plots import run as plots_run
from openfdk.plots.parallel import MAX_WORKERS, FigureError, balanced_shares, plot_workers, write_figures
from openfdk.results.run import read_results

needs_fork = pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="no fork here")


@pytest.fixture(scope="module")
def run_inputs(tmp_path_factory):
    """(model file, trial file) of the two-body run."""
    d = tmp_path_factory.mktemp("inputs")
    model = d / "model.yaml"
    model.write_text(yaml.safe_dump(two_body_model_dict(), sort_keys=False))
    _t, labels, x, _truth = synthetic_markers(20, rate=100.0, noise=0.0)
    write_c3d(d / "trial.c3d", labels, x, 100.0, units="mm")
    return model, d / "trial.c3d"


@pytest.fixture(scope="module")
def run_dir(run_inputs, tmp_path_factory):
    """The result folder of one two-body run (no figures)."""
    model, trial = run_inputs
    out = tmp_path_factory.mktemp("run") / "res"
    # (its frames fail recruitment: the figures shade them red)
    assert main(["run", str(model), str(trial), "--out", str(out), "--no-progress", "--no-plots",
                 "--max-failed", "1", "-q"]) == 0
    return out


@needs_fork
def test_figures_drawn_in_workers_are_the_ones_drawn_here_byte_for_byte(run_dir, tmp_path):
    here = write_figures(read_results(run_dir), tmp_path / "here", workers=1)
    workers = write_figures(read_results(run_dir), tmp_path / "workers", workers=2)
    assert len(here) >= 3
    assert [p.name for p in workers] == [p.name for p in here]
    for a, b in zip(here, workers):
        assert a.read_bytes() == b.read_bytes(), a.name


@needs_fork
def test_the_figures_are_drawn_in_other_processes(run_dir, tmp_path, monkeypatch):
    pids = tmp_path / "pids"
    pids.mkdir()
    original = plots_run._convergence

    def convergence(*args):  # inherited by the forked workers
        (pids / str(os.getpid())).touch()
        return original(*args)

    monkeypatch.setattr(plots_run, "_convergence", convergence)
    write_figures(read_results(run_dir), tmp_path / "plots", workers=2)
    drawn_in = [int(p.name) for p in pids.iterdir()]
    assert len(drawn_in) == 1 and drawn_in[0] != os.getpid()


@needs_fork
def test_a_figure_that_fails_in_a_worker_is_named_and_the_others_are_written(run_dir, tmp_path, monkeypatch):
    def broken(*args):
        raise ValueError("no such column 'x'")

    monkeypatch.setattr(plots_run, "_kinematics", broken)
    out = tmp_path / "plots"
    with pytest.raises(FigureError, match=r"1 of \d+ figures not written \(kinematics: ValueError: no such column 'x'\)") as exc:
        write_figures(read_results(run_dir), out, workers=2)
    assert not (out / "kinematics.png").exists()
    assert exc.value.written and all(p.is_file() and p.stat().st_size > 1000 for p in exc.value.written)
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in exc.value.written)


@needs_fork
def test_a_planted_link_at_a_figure_is_refused_before_any_worker_starts(run_dir, tmp_path):
    out = tmp_path / "plots"
    out.mkdir()
    target = tmp_path / "precious.txt"
    target.write_text("precious\n")
    (out / "convergence.png").symlink_to(target)
    with pytest.raises(OutputDirError, match="convergence.png' is a symbolic link"):
        write_figures(read_results(run_dir), out, workers=2)
    assert target.read_text() == "precious\n"
    assert [p.name for p in out.iterdir()] == ["convergence.png"]  # nothing drawn


def _best_split(weights, m):
    """The smallest largest load of any split of ``weights`` into m groups (exhaustive)."""
    best = np.inf
    for labels in itertools.product(range(m), repeat=len(weights)):
        loads = np.zeros(m)
        np.add.at(loads, list(labels), weights)
        best = min(best, loads.max())
    return best


def test_the_shares_cover_every_figure_once_within_graham_s_bound():
    rng = np.random.default_rng(7)
    for n in range(1, 8):
        for m in (1, 2, 3):
            w = list(rng.integers(1, 50, n).astype(float))
            shares = balanced_shares(w, m)
            assert sorted(i for s in shares for i in s) == list(range(n))
            assert len(shares) == min(m, n) and all(s == sorted(s) for s in shares)
            largest = max(sum(w[i] for i in s) for s in shares)
            # LPT's makespan is at most (4/3 − 1/(3m)) of the optimum (Graham 1969)
            assert largest <= (4 / 3 - 1 / (3 * m)) * _best_split(w, m) + 1e-9
    # DM's run: the body poses' figure (46 axes) alone, the eight others together
    assert balanced_shares([46] + [4] * 8, 2) == [[0], list(range(1, 9))]


def test_the_workers_setting(monkeypatch):
    monkeypatch.delenv("OPENFDK_PLOT_WORKERS", raising=False)
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    forks = "fork" in multiprocessing.get_all_start_methods()
    assert plot_workers() == (min(MAX_WORKERS, cpus) if forks else 1)
    for raw, n in (("1", 1), (" 3 ", 3)):
        monkeypatch.setenv("OPENFDK_PLOT_WORKERS", raw)
        assert plot_workers() == (n if "fork" in multiprocessing.get_all_start_methods() else 1)
    for raw in ("0", "-2", "two", "1.5"):
        monkeypatch.setenv("OPENFDK_PLOT_WORKERS", raw)
        if "fork" in multiprocessing.get_all_start_methods():
            with pytest.raises(ValueError, match=rf"OPENFDK_PLOT_WORKERS='{raw}': give a whole number ≥ 1"):
                plot_workers()


@pytest.mark.parametrize("extra", [[], ["--no-plots"], ["--chunks", "2", "--workers", "0"]])
def test_run_checks_the_contact_rims_once_in_a_figure_worker_or_here(run_inputs, tmp_path, monkeypatch, extra):
    """`openfdk run` (serial or chunked) computes its rim check beside the figures (in a
    worker when there are workers, here with --no-plots) and reports it here once, after
    the results were written."""
    import openfdk.contact.rim as rim

    reported = []

    def check(model, q):  # the rim check's computation: what it saw comes back as its result
        return [(os.getpid(), np.asarray(q).shape, (tmp_path / "out" / "forces.csv").is_file())]

    monkeypatch.setattr(rim, "contact_rim_frames", check)
    monkeypatch.setattr(rim, "report_contact_rims", lambda hits, time: reported.append((os.getpid(), hits, len(time))))
    monkeypatch.setenv("OPENFDK_PLOT_WORKERS", "2")
    model, trial = run_inputs
    plots = "--no-plots" not in extra
    args = ["run", str(model), str(trial), "--out", str(tmp_path / "out"), "--no-progress", "--max-failed", "1",
            "-q"] + extra
    assert main(args) == 0
    assert len(reported) == 1
    pid, hits, n_time = reported[0]
    assert pid == os.getpid() and n_time == 20
    (computed_in, q_shape, written), = hits
    assert q_shape == (20, 14) and written  # two moving bodies' poses, after the results were written
    in_worker = plots and "fork" in multiprocessing.get_all_start_methods()
    assert (computed_in != os.getpid()) == in_worker
    assert (tmp_path / "out" / "plots" / "kinematics.png").is_file() == plots


def _side(log, fail=False, weight=1.0):
    """A SideJob that returns the pid it ran in and logs its report here."""
    from openfdk.plots.parallel import SideJob

    def compute():
        if fail:
            raise RuntimeError("rim check failed")
        return os.getpid()

    return SideJob(compute, log.append, weight)


def test_after_run_finishes_the_side_job_once_and_keeps_its_error_its_own(run_dir, tmp_path, monkeypatch, capsys):
    import shutil
    from types import SimpleNamespace

    from openfdk.cli.outputs import after_run

    monkeypatch.setenv("OPENFDK_PLOT_WORKERS", "2")
    out = tmp_path / "res"
    shutil.copytree(run_dir, out)
    args = SimpleNamespace(out=str(out), model=None, quiet=True, no_plots=False)
    log = []
    side = _side(log)
    after_run(args, side=side)
    assert len(log) == 1 and (out / "plots" / "convergence.png").is_file()
    if "fork" in multiprocessing.get_all_start_methods():
        assert log[0] != os.getpid()  # computed by a figure worker, reported here
    side.finish()
    assert len(log) == 1  # once

    # the figures fail before any worker starts (a planted link): the job is computed here
    (out / "plots" / "convergence.png").unlink()
    (out / "plots" / "convergence.png").symlink_to(tmp_path / "elsewhere.png")
    after_run(args, side=_side(log))
    assert log[1:] == [os.getpid()]
    assert "figures not written" in capsys.readouterr().err
    (out / "plots" / "convergence.png").unlink()

    # an error of the job itself (in its worker, then again here) is raised as its own,
    # after the figures, which are written
    with pytest.raises(RuntimeError, match="rim check failed"):
        after_run(args, side=_side(log, fail=True))
    assert "figures not written" not in capsys.readouterr().err
    assert (out / "plots" / "convergence.png").is_file()


@needs_fork
def test_a_side_job_heavier_than_the_figures_gets_a_worker_to_itself(run_dir, tmp_path, monkeypatch):
    """The side job is one more share of the LPT split (balanced_shares), weighed with the
    figures: heavier than all of them together, it is a share of its own, computed in a
    worker, and the other share holds every figure. (Which worker process takes which
    share is the pool's: on a loaded machine one process may take both in turn.)"""
    import openfdk.plots.parallel as parallel

    split = []
    original = parallel.balanced_shares

    def recorded(weights, workers):
        split.append((list(weights), original(weights, workers)))
        return split[-1][1]

    monkeypatch.setattr(parallel, "balanced_shares", recorded)
    results = read_results(run_dir)
    plan = plots_run.figure_plan(results)
    total = sum(w for _, _, w in plan)
    log = []
    side = _side(log, weight=2.0 * total)
    paths = write_figures(results, tmp_path / "plots", workers=2, side=side)
    assert log == []  # write_figures does not report it
    side.finish()
    assert len(paths) == len(plan) >= 3 and all(p.is_file() for p in paths)
    (weights, shares), = split
    assert weights == [w for _, _, w in plan] + [2.0 * total]  # the side job last, with the figures' units
    assert sorted(shares) == [list(range(len(plan))), [len(plan)]]  # alone; the figures together
    assert log[0] != os.getpid()  # computed in a worker


@needs_fork
def test_a_worker_that_is_killed_is_reported_with_the_figures_it_did_not_write(run_dir, tmp_path, monkeypatch):
    def killed(*args):  # in the worker: as if the kernel's out-of-memory killer stopped it
        os._exit(9)

    monkeypatch.setattr(plots_run, "_kinematics", killed)
    out = tmp_path / "plots"
    out.mkdir()
    (out / "kinematics.png").write_bytes(b"an earlier run's figure")
    planned = [name for name, _, _ in plots_run.figure_plan(read_results(run_dir))]
    with pytest.raises(FigureError, match=r"kinematics: its worker process stopped") as exc:
        write_figures(read_results(run_dir), out, workers=2)
    # (the pool stops its other worker too): every figure is either written or named missing
    named = {n for n in planned if f"{n}: " in str(exc.value)}
    written = {p.stem for p in exc.value.written}
    assert "kinematics" in named and named | written == set(planned) and not named & written
    assert all((out / f"{n}.png").is_file() for n in written)
    assert not any((out / f"{n}.png").exists() for n in named)  # the earlier run's file is gone too
    assert str(exc.value).startswith(f"{len(named)} of {len(planned)} figures not written")


@needs_fork
def test_a_side_job_whose_worker_is_killed_is_computed_here(run_dir, tmp_path):
    """The worker computing the side job is stopped (as by the out-of-memory killer): the
    figures it did not draw are named, and the job is computed again in this process, so
    the run's check is not lost."""
    from openfdk.plots.parallel import SideJob

    parent = os.getpid()
    log = []

    def compute():
        if os.getpid() != parent:
            os._exit(9)
        return "computed here"

    results = read_results(run_dir)
    total = sum(w for _, _, w in plots_run.figure_plan(results))
    side = SideJob(compute, log.append, 2.0 * total)  # a worker of its own
    try:
        paths = write_figures(results, tmp_path / "plots", workers=2, side=side)
    except FigureError as exc:  # (the pool may stop the figures' worker too)
        paths = exc.written
    assert all(p.is_file() for p in paths)
    side.finish()
    assert log == ["computed here"]
