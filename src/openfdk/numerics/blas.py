"""BLAS threads for openfdk's solves: one by default.

openfdk's matrices are small (tens to a few hundred rows), where a threaded BLAS spends
more time waking threads than multiplying: on a 2-core machine the full-body recruitment
took 10–18 ms per frame with OpenBLAS's default threads against 1.4–1.9 ms with one
(bench full_body_muscles, alternated).

numpy and scipy each bring their own OpenBLAS, and the compiled kernels' LAPACK calls use
scipy's (numba binds ``scipy.linalg.cython_lapack``). A limit set with threadpoolctl
reaches only the libraries already loaded, so scipy's is loaded before it. Until stop 57
the commands limited numpy's alone: DM's 100-frame run spent 19–21 s of CPU for 12–13 s
of wall time, and two runs side by side on the 2-core machine took 90 s each instead of
29 s (og9's stance).
"""

from __future__ import annotations

import contextlib
import os

#: the environment variable: a whole number of threads, 0 = as the BLAS library chooses
VARIABLE = "OPENFDK_BLAS_THREADS"


def blas_threads():
    """A context manager that limits every BLAS library (numpy's and scipy's) to
    ``OPENFDK_BLAS_THREADS`` threads (default 1; 0: no limit) inside it. Raises
    ValueError naming the variable when its value is not a whole number."""
    value = os.environ.get(VARIABLE, "1").strip()
    if not value.isdigit():
        raise ValueError(f"{VARIABLE}: expected a whole number of threads (0: no limit), got {value!r}")
    n = int(value)
    if n == 0:
        return contextlib.nullcontext()
    import numpy  # noqa: F401  (numpy's OpenBLAS)
    import scipy.linalg.cython_lapack  # noqa: F401  (scipy's, which the compiled kernels use)
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=n, user_api="blas")


__all__ = ["blas_threads", "VARIABLE"]
