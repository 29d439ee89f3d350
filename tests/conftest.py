"""Test-session set-up: a private distance-grid disk cache (openfdk.contact.grid_cache),
so the suite neither reads nor fills the user's cache. Dask workers started by the
tests inherit it through the environment."""

import os
import tempfile

os.environ["OPENFDK_CACHE_DIR"] = tempfile.mkdtemp(prefix="openfdk-test-cache-")
