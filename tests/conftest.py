import os

import pytest

from aerosid.simulation import load_case, simulate

# The estimator-bias check (aerosid.identification.bias_check) repeats every fit 2 x BIAS_PAIRS
# times: the suite runs without it (CLI subprocesses inherit this) except where a test asks for it
# (tests/identification/test_bias_check.py), to stay inside CI's time.
os.environ.setdefault("AEROSID_BIAS_PAIRS", "0")


@pytest.fixture(scope="session")
def reference_flight():
    """The seed-rlv reference flight, seed 0 (90 s at 100 Hz)."""
    return simulate(load_case("seed-rlv"), seed=0)


#: How long the test harness waits for its Prefect server [s]: 37-125 s were measured on a
#: loaded 2-core machine.  prefect_test_harness() has its own server_startup_timeout
#: (default 30 s) and does not read PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS
#: unless it is given None, so it is passed explicitly.
HARNESS_STARTUP_TIMEOUT_S = 600


def prefect_harness_context():
    """prefect_test_harness with a start-up wait long enough for a loaded machine."""
    from prefect.testing.utilities import prefect_test_harness

    return prefect_test_harness(server_startup_timeout=HARNESS_STARTUP_TIMEOUT_S)


@pytest.fixture(scope="session")
def prefect_harness(tmp_path_factory):
    """Prefect hermetically: a temporary PREFECT_HOME, no API URL, analytics off."""
    import os

    home = tmp_path_factory.mktemp("prefect-home")
    os.environ["PREFECT_HOME"] = str(home)
    os.environ.pop("PREFECT_API_URL", None)
    os.environ["PREFECT_SERVER_ANALYTICS_ENABLED"] = "false"
    os.environ["PREFECT_LOGGING_LEVEL"] = "WARNING"
    # the ephemeral servers flows start outside the harness (CLI subprocesses)
    os.environ["PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS"] = str(HARNESS_STARTUP_TIMEOUT_S)
    with prefect_harness_context():
        yield home


@pytest.fixture(scope="session")
def reference_run(reference_flight):
    """The whole method in memory on the reference flight (seed 0)."""
    from aerosid.ebm import process_telemetry
    from aerosid.vehicles.vehicle import load_vehicle

    return process_telemetry(reference_flight.telemetry, load_vehicle("seed-rlv"), flight="reference")
