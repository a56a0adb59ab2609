"""`aerosid simulate --jsbsim` does not print JSBSim's harmless re-open notices as errors
(aerosid.cli.simulate._reopened_output_notices_dropped)."""
import subprocess
import sys

import pytest

pytest.importorskip("jsbsim")


def test_an_aircraft_whose_xml_asks_for_an_output_file_simulates_without_error_lines(tmp_path):
    # pogo-jsbsim's XML asks for pogo.csv: JSBSim re-opens it at every initial-condition run
    # of the trim and the design (265 "ERROR: unable to open the file" lines before)
    done = subprocess.run([sys.executable, "-m", "aerosid.cli", "simulate", "--jsbsim", "pogo-jsbsim", "--seed", "0",
                           "--out", str(tmp_path / "pogo")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "unable to open" not in done.stdout + done.stderr
    assert "Note: 'idlefuelflow' is obsolete" in done.stdout  # JSBSim's other messages are still shown
    assert "wrote" in done.stdout and (tmp_path / "pogo" / "telemetry.parquet").is_file()
