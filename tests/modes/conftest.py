"""The price-law tests' feeder (tests/modes/price_laws.py)."""

from __future__ import annotations

import pytest
from price_laws import synthetic_1k


@pytest.fixture(scope="module")
def problem():
    """The synthetic 1k feeder, every candidate line limited (68 limited lines, nested)."""
    return synthetic_1k()
