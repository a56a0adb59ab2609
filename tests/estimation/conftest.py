import numpy as np
import pytest

from aerosid.estimation.synthetic import simulate_flight


@pytest.fixture(scope="session")
def flight():
    """80 s, 100 Hz synthetic RLV-like flight with the seed's noise levels."""
    return simulate_flight(duration_s=80.0, rate_hz=100.0, seed=3)


@pytest.fixture(scope="session")
def short_flight():
    return simulate_flight(duration_s=4.0, rate_hz=100.0, seed=5)


def col_rel_err(a, b):
    """max |a - b| relative to each column's max |b| (states have very different scales)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    sc = np.max(np.abs(b), axis=0)
    sc = np.where(sc > 0, sc, 1.0)
    return float(np.nanmax(np.abs(a - b) / sc))
