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


@pytest.mark.parametrize("plots", [True, False])
def test_run_checks_the_contact_rims_once_here_with_or_without_figures(run_inputs, tmp_path, monkeypatch, plots):
    import openfdk.contact.rim as rim

    calls = []

    def check(model, kin):  # the run's rim check, deferred by `openfdk run` to the figures' time
        calls.append((os.getpid(), np.asarray(kin.q).shape, len(kin.time), (tmp_path / "out" / "forces.csv").is_file()))

    monkeypatch.setattr(rim, "warn_contact_rims", check)
    model, trial = run_inputs
    args = ["run", str(model), str(trial), "--out", str(tmp_path / "out"), "--no-progress", "--max-failed", "1",
            "-q"] + ([] if plots else ["--no-plots"])
    assert main(args) == 0
    assert len(calls) == 1
    pid, q_shape, n_time, written = calls[0]
    assert pid == os.getpid() and q_shape == (20, 14) and n_time == 20  # two moving bodies
    assert written  # after the results were written, while (or instead of) the figures
    assert (tmp_path / "out" / "plots" / "kinematics.png").is_file() == plots


def test_after_run_makes_the_alongside_call_once_and_keeps_its_error_its_own(run_dir, tmp_path, monkeypatch, capsys):
    import shutil
    from types import SimpleNamespace

    from openfdk.cli.outputs import after_run

    out = tmp_path / "res"
    shutil.copytree(run_dir, out)
    args = SimpleNamespace(out=str(out), model=None, quiet=True, no_plots=False)
    calls = []
    after_run(args, alongside=lambda: calls.append(1))
    assert calls == [1] and (out / "plots" / "convergence.png").is_file()

    # the figures fail before any worker starts (a planted link): the call is still made once
    (out / "plots" / "convergence.png").unlink()
    (out / "plots" / "convergence.png").symlink_to(tmp_path / "elsewhere.png")
    after_run(args, alongside=lambda: calls.append(2))
    assert calls == [1, 2]
    assert "figures not written" in capsys.readouterr().err
    (out / "plots" / "convergence.png").unlink()

    # an error of the call itself is raised as its own, not reported as the figures'
    def broken():
        raise RuntimeError("rim check failed")

    with pytest.raises(RuntimeError, match="rim check failed"):
        after_run(args, alongside=broken)
    assert "figures not written" not in capsys.readouterr().err


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
