"""Shared fixtures: the IEEE European LV feeder and its key-node reduction (built once).

Under CI (``CI`` set) hypothesis draws its examples deterministically, so a CI run is
repeatable; local runs keep exploring new examples.

Tests never touch the user's cache: ``POPDISPATCH_CACHE_DIR`` points at a temporary folder for
the whole session (set here, before any test module is imported, so that module-level code and
the command-line subprocesses the tests start, which inherit the environment, use it too).
"""

import os
import tempfile

import pytest
from hypothesis import settings

from popdispatch.cache import CACHE_ENV
from popdispatch.cases import ieee_elv
from popdispatch.feeder import reduce_feeder

_TEST_CACHE = tempfile.TemporaryDirectory(prefix="popdispatch-test-cache-")
os.environ[CACHE_ENV] = _TEST_CACHE.name  # read at each use, so importing above is fine

settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.fixture(scope="session")
def elv():
    return ieee_elv()


@pytest.fixture(scope="session")
def elv_reduced():
    return reduce_feeder(ieee_elv())
