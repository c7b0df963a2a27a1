"""Shared fixtures: the IEEE European LV feeder and its key-node reduction (built once)."""

import pytest

from popdispatch.feeder import ieee_elv, reduce_feeder


@pytest.fixture(scope="session")
def elv():
    return ieee_elv()


@pytest.fixture(scope="session")
def elv_reduced():
    return reduce_feeder(ieee_elv())
