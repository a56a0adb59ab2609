"""Smoothing stage: a preprocessed segment -> smoothed states with sigma (method.md §2–§6).

A thin adapter between the preprocessed telemetry frame (``*_clean`` columns and
quality flags) and ``aerosid.estimation.smooth_flight``; it builds the
``SmoothedSegment`` frame (schemas/smoothed.py).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from aerosid.estimation import EBMOptions, EBMResult
from aerosid.estimation.adaptive import smooth_flight_adaptive
from aerosid.estimation.findings import (KEPT_SUSPECT_COLUMN, findings_mask, kept_note, kept_sensors, sample_interval,
                                         smoother_findings)
from aerosid.estimation.local_q import CONTROL_LEAD_S, CONTROL_SHARE, moving_controls
from aerosid.preprocess import usable_mask
from aerosid.vehicles.vehicle import Vehicle
from schemas.smoothed import RATE_DERIVATIVE_COLUMNS, STATE_COLUMNS

IMU_CHANNELS = ("ax_m_s2", "ay_m_s2", "az_m_s2", "p_rad_s", "q_rad_s", "r_rad_s")
CONTROL_CHANNELS = ("d1_rad", "d2_rad", "d3_rad", "d4_rad")  # for the local process noise (estimation.local_q)
MIN_USABLE_SAMPLES = 16  # the seven-point parabola fits and the spectra need some data
#: A segment whose condemned samples (gated runs, NIS excursions) exceed this share is failed.
MAX_SUSPECT_FRACTION = 0.5


@dataclass(frozen=True)
class SmoothedSegmentResult:
    segment_id: str
    frame: pd.DataFrame
    result: EBMResult
    findings: tuple = ()  # aerosid.estimation.findings.Finding: gated runs, NIS excursions, mean NIS
    process_noise_note: str = ""  # aerosid.estimation.adaptive: escalations of the chains' process noise

    def nonfinite(self) -> np.ndarray:
        """Samples whose smoothed state or sigma is not finite (a filter that ran off numerically)."""
        r = self.result
        return ~(np.isfinite(r.x_smooth).all(axis=1) & np.isfinite(r.sigma_smooth).all(axis=1))

    def lost_reason(self) -> str:
        """Why the segment is failed: states that are not finite, the divergence (with its
        samples) and the findings."""
        bad = self.nonfinite()
        if bad.any():
            t = self.result.t_s[bad]
            return (f"the filter ran off numerically: smoothed states not finite at {int(bad.sum())} of {bad.size} "
                    f"samples, t = {t[0]:.2f}..{t[-1]:.2f} s ({self.process_noise_note})")
        why = "; ".join(f.summary() for f in self.findings if f.cut)
        head = f"filter diverged: {self.divergence_note()}; " if self.result.diverged else ""
        return f"{head}more than half the samples condemned ({why})"

    @property
    def lost(self) -> bool:
        """More than half the segment is condemned (the ``suspect`` columns), or any smoothed
        state is not finite (no Parquet of smoothed states may hold one): not worth keeping."""
        if not len(self.frame) or self.nonfinite().any():
            return True
        condemned = self.frame["suspect"].to_numpy(bool).copy()
        for col in KEPT_SUSPECT_COLUMN.values():  # a sensor's own cuts count here too
            if col in self.frame:
                condemned |= self.frame[col].to_numpy(bool)
        return bool(condemned.mean() > MAX_SUSPECT_FRACTION)

    def divergence_note(self) -> str:
        """Where the filter's windowed NIS left its band (sample times) [s]."""
        r = self.result
        idx = np.asarray(r.divergence_samples, dtype=int)
        if idx.size == 0:
            return "no divergence"
        times = r.t_s[idx]
        return (f"NIS far outside its band at {idx.size} samples, t = {times[0]:.2f}..{times[-1]:.2f} s "
                f"(first samples {idx[:5].tolist()}); mean NIS filter {r.mean_nis_filter:.2f}, "
                f"band {r.nis_band[0]:.2f}..{r.nis_band[1]:.2f}")

    def nis_record(self) -> str:
        """The smoother's noise check as strict JSON (a NaN is written as null)."""
        r = self.result

        def num(v):
            return float(v) if np.isfinite(v) else None

        floor = r.R_sigma_white_floor if r.R_sigma_white_floor is not None else []
        return json.dumps({"process_noise": self.process_noise_note, "mean_nis_filter": num(r.mean_nis_filter),
                           "mean_nis_smoother": num(r.mean_nis_smoother), "band": list(map(num, r.nis_band)),
                           "R_sigma": list(map(num, r.R_sigma)), "R_sigma_dispersion": list(map(num, r.R_sigma_dispersion)),
                           "R_sigma_white_floor": list(map(num, floor)),
                           "channel_nis_filter": list(map(num, r.chan_nis_filter))}, allow_nan=False)


def smoothing_options(vehicle: Vehicle, overrides: dict | None = None) -> EBMOptions:
    """The vehicle file's smoother defaults ([estimation]) with the caller's overrides on top."""
    merged = {**vehicle.estimation, **(overrides or {})}
    return EBMOptions(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in merged.items()})


def _with_stated_chain_scale(findings: list, settings: dict) -> list:
    """A mean-NIS finding names a stated ``q_chain_scale`` (a vehicle file's [estimation] or the
    caller's): a per-vehicle constant copied from another vehicle's file (the first 737 check
    copied c172x's 1e3) sets the chains' process noise the flight would otherwise choose."""
    if "q_chain_scale" not in settings:
        return findings
    hint = (f"; the chains' process noise is scaled by the stated [estimation] q_chain_scale = "
            f"{list(settings['q_chain_scale'])}: leave it out to have the flight choose it")
    return [replace(f, detail=f.detail + hint) if f.kind == "nis_mean" else f for f in findings]


def _with_manoeuvre_hint(findings: list, t_s: np.ndarray, controls: np.ndarray | None, names: list[str]) -> list:
    """A `gated` finding says which controls moved over its span (aerosid.estimation.local_q's
    test): one channel out reads as a sensor fault and is cut from every channel's regression, but
    when a surface moved it may be a manoeuvre the filter could not follow in that channel alone
    (JSBSim F4N seed 1 logged at 50 Hz: a_x gated 30.6-32.4 s through the rudder doublet, the cut
    took the doublet and C_n,beta came out not determined; at 100 Hz nothing was gated)."""
    if controls is None or not findings:
        return findings
    t = np.asarray(t_s, float)
    lead = int(round(CONTROL_LEAD_S / sample_interval(t))) if t.size > 1 else 0
    out = []
    for f in findings:
        if f.kind == "gated":
            a, b = int(np.searchsorted(t, f.t0_s)), int(np.searchsorted(t, f.t1_s, side="right"))
            moved = [names[j] for j in moving_controls(controls, a, b, lead) or []]
            if moved:
                f = replace(f, detail=f.detail + (
                    f"; {', '.join(moved)} moved during it or in the {CONTROL_LEAD_S:g} s before (by at least "
                    f"{CONTROL_SHARE:.0%} of its range): if the sensor is sound this is a manoeuvre the filter could "
                    f"not follow in {f.channel} alone"
                    + (", and the cut takes that manoeuvre from every channel's regression" if f.cut else "")))
        out.append(f)
    return out


def smooth_segment_frame(rows: pd.DataFrame, vehicle: Vehicle, options: dict | None = None,
                         segment_id: str = "seg00") -> SmoothedSegmentResult:
    """Run the EKF + MBF smoother over one segment of a preprocessed frame;
    options: EBMOptions fields overriding the vehicle's [estimation] defaults."""
    t = rows["t_s"].to_numpy(dtype=float)
    z = rows[[f"{c}_clean" for c in IMU_CHANNELS]].to_numpy(dtype=float)
    valid = usable_mask(rows, list(IMU_CHANNELS)) & np.isfinite(z)
    counts = valid.sum(axis=0)
    if counts.min() < MIN_USABLE_SAMPLES:
        worst = IMU_CHANNELS[int(np.argmin(counts))]
        raise ValueError(f"segment {segment_id} (t = {t[0]:.2f}..{t[-1]:.2f} s): channel {worst} has "
                         f"{int(counts.min())} usable samples of {len(rows)} (the rest dropout or flagged); "
                         f"at least {MIN_USABLE_SAMPLES} per channel are needed to initialise the filter")
    filled = pd.DataFrame(z).interpolate(limit_direction="both").to_numpy()
    ctl = [f"{c}_clean" for c in CONTROL_CHANNELS if f"{c}_clean" in rows]
    opts = smoothing_options(vehicle, options)
    adaptive = smooth_flight_adaptive(t, np.where(valid, z, np.nan), valid,
                                      (vehicle.Ixx_kg_m2, vehicle.Iyy_kg_m2, vehicle.Izz_kg_m2, vehicle.Ixz_kg_m2),
                                      vehicle.accel_offset_m, z_filled=filled,
                                      options=opts,
                                      controls=rows[ctl].to_numpy(dtype=float) if ctl else None)
    res = adaptive.result
    data = {"t_s": t, "segment": np.full(len(t), segment_id, dtype=object)}
    for j, name in enumerate(res.state_names):
        data[STATE_COLUMNS[name]] = res.x_smooth[:, j]
    for j, name in enumerate(res.state_names):
        data[f"sigma_{STATE_COLUMNS[name]}"] = res.sigma_smooth[:, j]
    angacc, angacc_sigma = res.angular_acceleration()
    for j, col in enumerate(RATE_DERIVATIVE_COLUMNS):
        data[col] = angacc[:, j]
        data[f"sigma_{col}"] = angacc_sigma[:, j]
    for name, sig in zip(res.meas_names, res.R_sigma):  # the R the filter used, for the Cramér-Rao bounds
        data[f"R_sigma_{name}_{'m_s2' if name.startswith('a') else 'rad_s'}"] = np.full(len(t), float(sig))
    data["nis_filter"] = res.nis_filter
    data["nis_smoother"] = res.nis_smoother
    data["updated"] = res.used.any(axis=1)
    for j, m in enumerate(res.meas_names):
        data[f"gated_{m}"] = res.gate_flags[:, j]
    excursion = np.zeros(len(t), bool)
    excursion[np.asarray(res.divergence_samples, dtype=int)] = True
    findings, _ = smoother_findings(t, {m: res.gate_flags[:, j] for j, m in enumerate(res.meas_names)},
                                    excursion, res.mean_nis_filter, tuple(res.nis_band), segment_id,
                                    dict(zip(res.meas_names, map(float, res.chan_nis_filter))),
                                    dict(zip(res.meas_names, map(float, res.whiteness()))),
                                    opts.f_max_hz)
    findings = _with_stated_chain_scale(findings, {**vehicle.estimation, **(options or {})})
    # a sensor that feeds one channel alone (aerosid.estimation.findings.kept_sensors: a_x, and
    # with vanes a_y, a_z) costs only that channel: its gated runs are reported and marked for it,
    # the other channels keep the samples (JSBSim F4N seed 1 at 50 Hz: a_x gated through the rudder
    # doublet took the doublet from C_n's regression)
    kept = kept_sensors(vehicle.air_data_source)
    findings = [replace(f, cut=False, detail=f.detail + kept_note(f.channel, kept[f.channel]))
                if f.kind == "gated" and f.channel in kept else f for f in findings]
    findings = _with_manoeuvre_hint(findings, t, rows[ctl].to_numpy(dtype=float) if ctl else None,
                                    [c.removesuffix("_clean") for c in ctl])
    data["suspect"] = findings_mask(t, [f for f in findings if f.cut])
    for sensor in kept:
        data[KEPT_SUSPECT_COLUMN[sensor]] = findings_mask(t, [f for f in findings
                                                              if f.kind == "gated" and f.channel == sensor])
    frame = pd.DataFrame(data)
    frame["segment"] = frame["segment"].astype(str)
    return SmoothedSegmentResult(segment_id, frame, res, tuple(findings), adaptive.summary())
