"""Pandera model of the flight data the regression reads: air data, flight
coefficients (moments about the CG), recovered alpha/beta and the controls,
pooled over the segments of a flight (or of several flights)."""
from __future__ import annotations

from typing import Optional

import numpy as np
import pandas as pd
import pandera.pandas as pa

from pandera.typing import Series

def _f(unit: str, description: str = "", **checks) -> object:
    return pa.Field(metadata={"unit": unit, "description": description}, **checks)

class FlightData(pa.DataFrameModel):
    t_s: Series[float] = _f("s")
    flight: Series[str] = _f("-", "flight identifier")
    segment: Series[str] = _f("-", "segment id within the flight")
    V_m_s: Series[float] = _f("m/s", "navigation speed", gt=0)
    h_m: Series[float] = _f("m", "altitude", ge=-5000, le=81000)
    rho_kg_m3: Series[float] = _f("kg/m^3", "air density (US-1976 or measured: the file's aerosid.air_data "
                                            "metadata names the source per flight)", gt=0)
    mach: Series[float] = _f("-", "Mach number (source in aerosid.air_data)", gt=0)
    qbar_pa: Series[float] = _f("Pa", "dynamic pressure (source in aerosid.air_data)", gt=0)
    CA: Series[float] = _f("-", "axial force coefficient")
    CY: Series[float] = _f("-", "side force coefficient (+ right)")
    CN: Series[float] = _f("-", "normal force coefficient (+ up, = -C_z)")
    Cl: Series[float] = _f("-", "rolling moment coefficient")
    Cm: Series[float] = _f("-", "pitching moment coefficient about the CG")
    Cn: Series[float] = _f("-", "yawing moment coefficient about the CG")
    sigma_CN: Series[float] = _f("-", "1-sigma of CN from the smoother", ge=0)
    sigma_Cm: Series[float] = _f("-", "1-sigma of Cm from the smoother", ge=0)
    alpha_rad: Series[float] = _f("rad", "angle of attack from the database inversion", ge=-1.6, le=1.6)
    beta_rad: Series[float] = _f("rad", "sideslip from the database inversion", ge=-1.6, le=1.6)
    alpha_r_rad: Series[float] = _f("rad", "total angle of attack", ge=0, le=3.2)
    phi_r_rad: Series[float] = _f("rad", "aerodynamic roll angle", ge=-3.2, le=3.2)
    inversion_J: Series[float] = _f("-", "residual cost of the inversion", ge=0)
    delta_p_rad: Series[float] = _f("rad", "pitch deflection -d2+d4 (models use delta_p/2)")
    delta_y_rad: Series[float] = _f("rad", "yaw deflection -d1+d3 (models use delta_y/2)")
    delta_r_rad: Series[float] = _f("rad", "roll deflection d1+d2+d3+d4")
    p_rad_s: Series[float] = _f("rad/s", "smoothed roll rate")
    q_rad_s: Series[float] = _f("rad/s", "smoothed pitch rate")
    r_rad_s: Series[float] = _f("rad/s", "smoothed yaw rate")
    # errors in variables (aerosid.identification.eiv): white-noise 1-sigma whose band-limited
    # part is in the column named; optional (flight data written before them stays readable)
    eiv_sigma_alpha_rad: Optional[Series[float]] = _f("rad", "white noise in alpha_rad (vanes or inversion)", ge=0)
    eiv_sigma_beta_rad: Optional[Series[float]] = _f("rad", "white noise in beta_rad (vanes or inversion)", ge=0)
    eiv_sigma_p_rad_s: Optional[Series[float]] = _f("rad/s", "gyro white noise in p_rad_s (before the band "
                                                    "low-pass; 0: the rates are taken as exact)", ge=0)
    eiv_sigma_q_rad_s: Optional[Series[float]] = _f("rad/s", "gyro white noise in q_rad_s (before the band "
                                                    "low-pass; 0: the rates are taken as exact)", ge=0)
    eiv_sigma_r_rad_s: Optional[Series[float]] = _f("rad/s", "gyro white noise in r_rad_s (before the band "
                                                    "low-pass; 0: the rates are taken as exact)", ge=0)
    eiv_sigma_delta_p_rad: Optional[Series[float]] = _f("rad", "surface-sensor white noise in delta_p_rad (before "
                                                        "the band low-pass; 0: none found)", ge=0, nullable=True)
    eiv_sigma_delta_y_rad: Optional[Series[float]] = _f("rad", "surface-sensor white noise in delta_y_rad (before "
                                                        "the band low-pass; 0: none found)", ge=0, nullable=True)
    eiv_sigma_delta_r_rad: Optional[Series[float]] = _f("rad", "surface-sensor white noise in delta_r_rad (before "
                                                        "the band low-pass; 0: none found)", ge=0, nullable=True)
    # the band path's regressor signals before its low-pass (aerosid.identification.band_order.
    # WIDEBAND_COLUMNS), for the band order of non-linear terms; optional (smoother path, older files)
    # and nullable (flight data pooled with older files)
    alpha_wideband_rad: Optional[Series[float]] = _f("rad", "alpha before the band's low-pass (vanes, or inverted "
                                                     "from the smoother's accelerations)", nullable=True)
    beta_wideband_rad: Optional[Series[float]] = _f("rad", "beta before the band's low-pass", nullable=True)
    p_wideband_rad_s: Optional[Series[float]] = _f("rad/s", "the smoother's roll rate (before the band)", nullable=True)
    q_wideband_rad_s: Optional[Series[float]] = _f("rad/s", "the smoother's pitch rate (before the band)", nullable=True)
    r_wideband_rad_s: Optional[Series[float]] = _f("rad/s", "the smoother's yaw rate (before the band)", nullable=True)
    delta_p_wideband_rad: Optional[Series[float]] = _f("rad", "delta_p before the band's low-pass", nullable=True)
    delta_y_wideband_rad: Optional[Series[float]] = _f("rad", "delta_y before the band's low-pass", nullable=True)
    delta_r_wideband_rad: Optional[Series[float]] = _f("rad", "delta_r before the band's low-pass", nullable=True)
    V_wideband_m_s: Optional[Series[float]] = _f("m/s", "airspeed before the band's low-pass", gt=0, nullable=True)
    # rows whose force coefficient reads a sample condemned on the one sensor it alone reads
    # (aerosid.estimation.findings.kept_sensors: a_x, and with vanes a_y, a_z), kept for the other
    # channels; a fit of that channel leaves them out (aerosid.identification.identify.window_rows)
    cut_CA: Optional[Series[bool]] = _f("-", "CA reads an a_x sample condemned by a finding: not in CA's fit")
    cut_CY: Optional[Series[bool]] = _f("-", "CY reads an a_y sample condemned by a finding: not in CY's fit")
    cut_CN: Optional[Series[bool]] = _f("-", "CN reads an a_z sample condemned by a finding: not in CN's fit")

    class Config:
        strict = False
        coerce = False

    @pa.dataframe_check(name="all_finite")
    def _finite(cls, df: pd.DataFrame) -> pd.Series:
        num = df.select_dtypes(include=[np.number])
        return pd.Series(np.all(np.isfinite(num.to_numpy(dtype=float)), axis=1), index=df.index)
