"""The congestion minute (566, path 505-666 limited to 28 kW) for the agents' tests; it uses
the official loads of minute 566 that pandapower ships, so no data folder is needed."""

import pytest


@pytest.fixture(scope="session")
def congestion_problem():
    from popdispatch.scenarios import CONGESTION_PATH, elv_problem, peak_profiles

    return elv_problem(peak_profiles(), [CONGESTION_PATH])
