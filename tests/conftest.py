import numpy as np
import pytest


def observed_order(sizes, errors):
    """Least-squares slope of log(error) against log(size)."""
    return float(np.polyfit(np.log(sizes), np.log(errors), 1)[0])


@pytest.fixture
def order_of():
    return observed_order
