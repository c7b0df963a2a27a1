"""Shared fixtures: the IEEE European LV feeder and its key-node reduction (built once).

Under CI (``CI`` set) hypothesis draws its examples deterministically, so a CI run is
repeatable; local runs keep exploring new examples.
"""

import os

import pytest
from hypothesis import settings

from popdispatch.feeder import ieee_elv, reduce_feeder

settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.fixture(scope="session")
def elv():
    return ieee_elv()


@pytest.fixture(scope="session")
def elv_reduced():
    return reduce_feeder(ieee_elv())
