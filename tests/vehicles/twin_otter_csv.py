"""Write a flight-test CSV (degrees, g, ft, knots, lbf/ft^2, slug/ft^3) from a SIDPAC
Twin Otter file, as a data system would deliver it; read back with
aerosid/data/examples/twin-otter-018.map.toml it must give the SIDPAC import's telemetry.

    python -m tests.vehicles.twin_otter_csv lon_020213f1_018.mat flight.csv
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.vehicles.sidpac import import_sidpac
from aerosid.vehicles.units import TARGET_UNITS, pint_spelling, registry

#: CSV column -> (raw telemetry column, unit in the CSV); the aileron is one channel
#: (the right aileron, + trailing edge down): the map gives d2 = -aileron.
CSV_COLUMNS: dict[str, tuple[str, str]] = {
    "time": ("t_s", "s"), "tas_kt": ("V_m_s", "kt"), "alt_ft": ("h_m", "ft"),
    "ax_g": ("ax_m_s2", "g"), "ay_g": ("ay_m_s2", "g"), "az_g": ("az_m_s2", "g"),
    "p_dps": ("p_rad_s", "deg/s"), "q_dps": ("q_rad_s", "deg/s"), "r_dps": ("r_rad_s", "deg/s"),
    "elevator_deg": ("d1_rad", "deg"), "aileron_deg": ("d3_rad", "deg"), "rudder_deg": ("d4_rad", "deg"),
    "alpha_deg": ("alpha_vane_rad", "deg"), "beta_deg": ("beta_vane_rad", "deg"),
    "phi_deg": ("phi_rad", "deg"), "theta_deg": ("theta_rad", "deg"),
    "qbar_psf": ("qbar_pa", "lbf/ft^2"), "rho_slug_ft3": ("rho_kg_m3", "slug/ft^3"),
}


def twin_otter_csv_frame(mat_path: str | Path) -> pd.DataFrame:
    """The SIDPAC import's telemetry in flight-test units, one CSV column per entry of CSV_COLUMNS."""
    tel = import_sidpac(mat_path).telemetry
    ureg = registry()
    out = {}
    for name, (raw, unit) in CSV_COLUMNS.items():
        si = ureg.Quantity(tel[raw].to_numpy(float), TARGET_UNITS[raw])
        out[name] = np.asarray(si.to(pint_spelling(unit)).magnitude, dtype=float)
    return pd.DataFrame(out)


def write_twin_otter_csv(mat_path: str | Path, csv_path: str | Path) -> Path:
    """Write the CSV (floats as their shortest exact repr: the round trip loses nothing)."""
    csv_path = Path(csv_path)
    twin_otter_csv_frame(mat_path).to_csv(csv_path, index=False)  # shortest repr: exact round trip
    return csv_path


if __name__ == "__main__":  # pragma: no cover
    print(write_twin_otter_csv(sys.argv[1], sys.argv[2]))
