import pytest

from aerosid.simulation import load_case, simulate


@pytest.fixture(scope="session")
def reference_flight():
    """The seed-rlv reference flight, seed 0 (90 s at 100 Hz)."""
    return simulate(load_case("seed-rlv"), seed=0)


@pytest.fixture(scope="session")
def prefect_harness(tmp_path_factory):
    """Prefect hermetically: a temporary PREFECT_HOME, no API URL, analytics off."""
    import os

    home = tmp_path_factory.mktemp("prefect-home")
    os.environ["PREFECT_HOME"] = str(home)
    os.environ.pop("PREFECT_API_URL", None)
    os.environ["PREFECT_SERVER_ANALYTICS_ENABLED"] = "false"
    os.environ["PREFECT_LOGGING_LEVEL"] = "WARNING"
    os.environ["PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS"] = "180"  # a loaded 2-core CI box
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=180):  # its own default (30 s) ignores the variable above
        yield home


@pytest.fixture(scope="session")
def reference_run(reference_flight):
    """The whole method in memory on the reference flight (seed 0)."""
    from aerosid.ebm import process_telemetry
    from aerosid.vehicle import load_vehicle

    return process_telemetry(reference_flight.telemetry, load_vehicle("seed-rlv"), flight="reference")
