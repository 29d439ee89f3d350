"""Test-session set-up: a private distance-grid disk cache (openfdk.contact.grid_cache),
so the suite neither reads nor fills the user's cache. Dask workers started by the
tests inherit it through the environment.

The cache is made once per session, by pytest's controlling process, shared by the
xdist workers (they inherit the environment) and removed when the controlling process
exits: a session leaves nothing in the temporary folder (each one had left up to 0.6 GB;
494 of them held 48 GB on the development machine).
"""

import atexit
import os
import shutil
import tempfile

_SHARED = "OPENFDK_TEST_SESSION_CACHE"

if os.environ.get("PYTEST_XDIST_WORKER") and os.environ.get(_SHARED):
    os.environ["OPENFDK_CACHE_DIR"] = os.environ[_SHARED]
else:
    _cache = tempfile.mkdtemp(prefix="openfdk-test-cache-")
    os.environ["OPENFDK_CACHE_DIR"] = os.environ[_SHARED] = _cache
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)
