import pytest

from aerosid.simulation import load_case, simulate


@pytest.fixture(scope="session")
def reference_flight():
    """The seed-rlv reference flight, seed 0 (90 s at 100 Hz)."""
    return simulate(load_case("seed-rlv"), seed=0)
