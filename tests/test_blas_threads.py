"""The command line limits BLAS to OPENFDK_BLAS_THREADS threads (default 1): openfdk's
matrices are small, where a threaded BLAS costs more than it gives (cli/commands.py)."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from openfdk.cli.commands import _blas_threads, main


def _blas_libraries():
    """{path: threads} of every loaded BLAS library."""
    return {p["filepath"]: p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}


def test_commands_run_with_one_blas_thread_by_default(monkeypatch):
    np.ones((4, 4)) @ np.ones((4, 4))  # BLAS loaded
    monkeypatch.delenv("OPENFDK_BLAS_THREADS", raising=False)
    with _blas_threads():
        assert _blas_libraries() and set(_blas_libraries().values()) == {1}
    monkeypatch.setenv("OPENFDK_BLAS_THREADS", "0")
    outside = _blas_libraries()
    with _blas_threads():
        assert _blas_libraries() == outside  # 0: left as the library chose


def test_a_bad_thread_count_is_one_line(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("OPENFDK_BLAS_THREADS", "two")
    code = main(["check", str(tmp_path / "missing.yaml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "OPENFDK_BLAS_THREADS" in err[0] and "'two'" in err[0]


def test_the_limit_reaches_scipys_blas_loaded_after_it(tmp_path):
    """scipy brings its own OpenBLAS, which the compiled kernels' LAPACK calls use; a command
    loads it after the limit is set. In a fresh interpreter whose OpenBLAS defaults to two
    threads, every BLAS loaded inside the command's limit, scipy's included, runs one."""
    import json
    import os
    import subprocess
    import sys

    script = ("import json, numpy\n"
              "from threadpoolctl import threadpool_info\n"
              "from openfdk.cli.commands import _blas_threads\n"
              "with _blas_threads():\n"
              "    import scipy.linalg\n"
              "    scipy.linalg.lu_factor(numpy.eye(3))\n"
              "    print(json.dumps([(p['filepath'], p['num_threads']) for p in threadpool_info()\n"
              "                      if p['user_api'] == 'blas']))\n")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "2"}
    env.pop("OPENFDK_BLAS_THREADS", None)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, check=True)
    libraries = json.loads(out.stdout.strip().splitlines()[-1])
    assert any("scipy" in path for path, _ in libraries)  # scipy's own BLAS is among them
    assert {n for _, n in libraries} == {1}, libraries


def test_the_python_api_runs_with_one_blas_thread_and_restores_the_setting(monkeypatch):
    """openfdk.run limits BLAS as the commands do, inside the run only. (A BLAS another
    package brings, built without threads, stays at one whatever the caller sets: only
    the libraries that take the caller's two threads are compared.)"""
    import openfdk
    import openfdk.analysis.jobs as jobs
    from openfdk.api import result

    seen = []

    def run_job(*args, **kwargs):
        seen.append(_blas_libraries())
        return None, None, {}

    class Model:
        pass

    monkeypatch.delenv("OPENFDK_BLAS_THREADS", raising=False)
    monkeypatch.setattr(jobs, "run_job", run_job)
    monkeypatch.setattr(result.Result, "from_analysis", classmethod(lambda cls, *a, **k: "result"))
    import scipy.linalg  # noqa: F401  (both BLAS libraries loaded, so that both are seen)

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=2, user_api="blas"):  # a caller's setting of two threads
        before = _blas_libraries()
        two = [path for path, n in before.items() if n == 2]
        assert any("numpy" in path for path in two) and any("scipy" in path for path in two)
        assert openfdk.run(Model()) == "result"
        assert seen and all(seen[0][path] == 1 for path in two)
        assert _blas_libraries() == before  # restored
    monkeypatch.setenv("OPENFDK_BLAS_THREADS", "many")
    with pytest.raises(ValueError, match="OPENFDK_BLAS_THREADS.*'many'"):
        openfdk.run(Model())
