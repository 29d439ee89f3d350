"""The command line limits BLAS to OPENFDK_BLAS_THREADS threads (default 1): openfdk's
matrices are small, where a threaded BLAS costs more than it gives (cli/commands.py)."""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_info

from openfdk.cli.commands import _blas_threads, main


def _blas_counts():
    return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]


def test_commands_run_with_one_blas_thread_by_default(monkeypatch):
    np.ones((4, 4)) @ np.ones((4, 4))  # BLAS loaded
    monkeypatch.delenv("OPENFDK_BLAS_THREADS", raising=False)
    with _blas_threads():
        assert _blas_counts() and set(_blas_counts()) == {1}
    monkeypatch.setenv("OPENFDK_BLAS_THREADS", "0")
    outside = _blas_counts()
    with _blas_threads():
        assert _blas_counts() == outside  # 0: left as the library chose


def test_a_bad_thread_count_is_one_line(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("OPENFDK_BLAS_THREADS", "two")
    code = main(["check", str(tmp_path / "missing.yaml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "OPENFDK_BLAS_THREADS" in err[0] and "'two'" in err[0]
