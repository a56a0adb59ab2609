"""The SIDPAC Twin Otter flights (/work/shared/data/sidpac-twin-otter, real flight data)
as raw telemetry in aerosid's contract, and a vehicle file for them, for the tests of
the unit check (no false alarm on real data).  A small stand-in for the importer
(`aerosid import sidpac`): columns from SIDPAC's fdata layout (README there), converted
to SI and radians; the one aileron channel is split into left = +aileron, right =
-aileron; the vanes are SIDPAC's alpha and beta."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

DATA = Path(__file__).parent / "data" / "sidpac-twin-otter"  # public NASA data, copied with its README
FLIGHTS = ("lon_020213f1_017.mat", "lon_020213f1_018.mat")

VEHICLE_TOML = """
name = "twin-otter"
class = "aircraft"
description = "NASA Langley DHC-6 Twin Otter (SIDPAC demo data), values from the data files"
[mass]
mass_kg = 4944.0
Ixx_kg_m2 = 28353.0
Iyy_kg_m2 = 32910.0
Izz_kg_m2 = 52168.0
Ixz_kg_m2 = 1528.0
[reference]
S_m2 = 39.25
chord_m = 1.98
span_m = 19.81
x_cg_m = 0.0
[sensors]
accel_offset_m = [0.325, -0.421, 0.625]
[air_data]
source = "vanes"
[controls]
surfaces = ["elevator", "left_aileron", "right_aileron", "rudder"]
mixing = [[0.0, 0.5, -0.5, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
surface_limit_rad = 0.35
[aero]
mach_reference = 0.216
"""


def available() -> bool:
    return all((DATA / f).is_file() for f in FLIGHTS)


def telemetry(name: str) -> pd.DataFrame:
    import scipy.io

    f = scipy.io.loadmat(DATA / name, squeeze_me=True, struct_as_record=False)["fdata"]
    d, g, ft = np.pi / 180.0, 9.80665, 0.3048
    col = lambda k: np.asarray(f[:, k - 1], dtype=float)  # noqa: E731  (SIDPAC's 1-based columns)
    return pd.DataFrame({
        "t_s": col(1) - col(1)[0],
        "ax_m_s2": col(11) * g, "ay_m_s2": col(12) * g, "az_m_s2": col(13) * g,
        "p_rad_s": col(5) * d, "q_rad_s": col(6) * d, "r_rad_s": col(7) * d,
        "d1_rad": col(14) * d, "d2_rad": col(15) * d, "d3_rad": -col(15) * d, "d4_rad": col(16) * d,
        "V_m_s": col(2) * ft, "h_m": col(30) * ft,
        "alpha_vane_rad": col(4) * d, "beta_vane_rad": col(3) * d,
    })


def vehicle_file(folder: Path) -> Path:
    path = folder / "twin-otter.toml"
    path.write_text(VEHICLE_TOML)
    return path
