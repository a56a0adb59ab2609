"""Predict another manoeuvre with a run's identified model (``aerosid validate``).

Two checks, both on a manoeuvre the model was not fitted to:

* **coefficient prediction**: the other manoeuvre's telemetry goes through the same
  estimation (EBM, with the run's own preprocessing and smoothing settings) to its
  flight data; each channel's coefficient is predicted from that flight data's
  regressors and compared with the flight-derived coefficient;
* **output prediction**: the model is simulated driven by the manoeuvre's measured
  controls, airspeed, dynamic pressure and attitude, from its measured initial
  state, and alpha, q, a_z (beta, p, r, a_y for a lateral model) are compared with
  the measurements (``aerosid.identification.output_prediction``).

Each comparison reports Theil's inequality coefficient (TIC, 0 perfect; SIDPAC and
Morelli & Klein read TIC <= 0.25..0.3 as a good predictor), the RMS error and the
RMS error over the measured signal's standard deviation (TIC of a signal with a
large mean, a_z or a trimmed alpha, is small whatever the dynamics; RMS/std is not).
Only samples inside the identification's Mach window are predicted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.identification.identified import (IdentifiedModel, load_identified_model, read_run_json,
                                               with_preflight_identities)
from aerosid.identification.output_prediction import (AXIS_CHANNELS, AXIS_OUTPUTS, BIAS_MODES, OUTPUT_UNITS,
                                                      predict_axis, prediction_inputs,
                                                      theil_inequality)
from aerosid.identification.flight_data import vane_angles
from aerosid.identification.identify import mach_window_mask
from aerosid.modelling.models import vehicle_signals
from aerosid.vehicles.vehicle import Vehicle

MIN_SPAN_S = 1.0  # contiguous in-window stretches shorter than this are not predicted
ATTITUDE_COLUMNS = ("phi_rad", "theta_rad")
AXES_CHOICES = ("auto", "lon", "lat", "both")


@dataclass(frozen=True)
class FitMetric:
    """Prediction error of one signal: n samples; TIC; RMS error [unit]; RMS / std of
    the measured signal; the mean offset removed [unit] (NaN: none); measured by what."""

    name: str
    unit: str
    n: int
    tic: float
    rms: float
    nrms: float
    offset: float
    source: str

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in self.__dict__.items()}


def fit_metric(name: str, unit: str, measured, predicted, offset: float = float("nan"), source: str = "") -> FitMetric:
    y, yh = np.asarray(measured, float), np.asarray(predicted, float)
    ok = np.isfinite(y) & np.isfinite(yh)
    y, yh = y[ok], yh[ok]
    if y.size == 0:
        return FitMetric(name, unit, 0, float("nan"), float("nan"), float("nan"), offset, source)
    rms = float(np.sqrt(np.mean((y - yh) ** 2)))
    sd = float(np.std(y))
    return FitMetric(name, unit, int(y.size), theil_inequality(y, yh), rms, rms / sd if sd > 0 else float("nan"),
                     offset, source)


@dataclass(frozen=True)
class ValidationResult:
    """The prediction of one manoeuvre by a run's model (see module docstring)."""

    run_dir: str
    telemetry: str
    model: IdentifiedModel = field(repr=False)
    vehicle: str
    bias: str
    mach_window: tuple  # (low, high) Mach of the samples predicted
    n_samples: int  # flight-data samples of the other manoeuvre
    n_predicted: int  # of which inside the Mach window, in spans >= MIN_SPAN_S
    coefficients: tuple  # FitMetric per channel
    outputs: tuple  # FitMetric per simulated output
    coefficient_frame: pd.DataFrame = field(repr=False)  # t_s, span, measured_<ch>, predicted_<ch>
    predictions: tuple = field(repr=False)  # AxisPrediction per simulated axis
    intercepts: dict = field(default_factory=dict)  # coefficient -> (identified or preflight, re-estimated)
    sources: dict = field(default_factory=dict)  # density, attitude, ... -> where from
    notes: tuple = ()

    @property
    def n_spans(self) -> int:
        sp = self.coefficient_frame["span"].to_numpy()
        return int(np.unique(sp[sp >= 0]).size)

    def metric(self, name: str) -> FitMetric:
        for m in (*self.coefficients, *self.outputs):
            if m.name == name:
                return m
        raise KeyError(f"no metric {name!r}; have {[m.name for m in (*self.coefficients, *self.outputs)]}")

    def summary(self) -> str:
        bias = {"none": "none (the model as identified)",
                "offsets": "output offsets (mean of measured - predicted per output and span, as SIDPAC's "
                           "prediction)",
                "intercepts": "intercepts re-estimated on this manoeuvre by output error, plus output offsets",
                }[self.bias]
        lines = [f"validation of {self.run_dir} on {self.telemetry}",
                 f"  model {self.model.source}; vehicle {self.vehicle}",
                 f"  {self.n_predicted} of {self.n_samples} samples predicted in {self.n_spans} span(s) (each "
                 f"simulated from its own initial state), Mach {self.mach_window[0]:.3g}..{self.mach_window[1]:.3g}; "
                 f"bias treatment: {bias}"]
        lines += [f"  {k}: {v}" for k, v in self.sources.items()]
        head = f"  {'':<10}{'unit':<8}{'N':>6}{'TIC':>8}{'RMS':>12}{'RMS/std':>9}{'offset':>12}  measured by"
        if self.coefficients:
            lines += ["coefficient prediction (the model on the other manoeuvre's flight data)", head]
            lines += [_row(m) for m in self.coefficients]
        if self.outputs:
            lines += ["output prediction (the model simulated with the measured controls)", head]
            lines += [_row(m) for m in self.outputs]
            ang = [m for m in self.outputs if m.unit == "rad"]
            if ang:
                lines.append("  angles in degrees: " + ", ".join(f"{m.name} RMS {math.degrees(m.rms):.3g} deg"
                                                                  for m in ang))
        for k, (a, b) in self.intercepts.items():
            lines.append(f"  {k} re-estimated: {a:.5g} -> {b:.5g}")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {"run_dir": self.run_dir, "telemetry": self.telemetry, "model": self.model.source,
                "vehicle": self.vehicle, "bias": self.bias, "mach_window": list(self.mach_window),
                "n_samples": self.n_samples, "n_predicted": self.n_predicted, "n_spans": self.n_spans,
                "coefficients": [m.as_dict() for m in self.coefficients],
                "outputs": [m.as_dict() for m in self.outputs],
                # the start of a re-estimated intercept: the run's estimate, or (an identity channel's) the preflight's
                "intercepts": {k: {("identified" if math.isfinite(self.model.values.get(k, math.nan)) else "preflight"): a,
                                   "re_estimated": b} for k, (a, b) in self.intercepts.items()},
                "sources": dict(self.sources), "notes": list(self.notes),
                "model_coefficients": {k: (v if math.isfinite(v) else None) for k, v in self.model.values.items()}}


def _row(m: FitMetric) -> str:
    def f(x, spec):
        return format(x, spec) if math.isfinite(x) else "-"
    return (f"  {m.name:<10}{m.unit:<8}{m.n:>6}{f(m.tic, '.3f'):>8}{f(m.rms, '.4g'):>12}{f(m.nrms, '.3f'):>9}"
            f"{f(m.offset, '.4g'):>12}  {m.source}")


# --------------------------------------------------------------------------- pieces
def spans_of(fd: pd.DataFrame, keep: np.ndarray, min_span_s: float = MIN_SPAN_S) -> np.ndarray:
    """Span id per row: contiguous kept rows of one segment without a time hole
    (> 1.5 median steps); -1 for rows not kept or in spans shorter than min_span_s."""
    t = fd["t_s"].to_numpy(float)
    seg = fd["segment"].astype(str).to_numpy() if "segment" in fd else np.zeros(len(fd), str)
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    span = np.full(len(fd), -1)
    k, start = -1, None
    for i in range(len(fd)):
        new = (i == 0 or not keep[i - 1] or seg[i] != seg[i - 1] or t[i] - t[i - 1] > 1.5 * step
               or t[i] <= t[i - 1])
        if keep[i]:
            if new:
                k += 1
            span[i] = k
    out = np.full(len(fd), -1)
    n = 0
    for s in range(k + 1):
        rows = span == s
        if t[rows][-1] - t[rows][0] >= min_span_s:
            out[rows] = n
            n += 1
    return out


def _offset_per_span(meas, pred, span) -> np.ndarray:
    off = np.full(len(meas), np.nan)
    for s in np.unique(span[span >= 0]):
        rows = span == s
        d = meas[rows] - pred[rows]
        off[rows] = np.nanmean(d) if np.isfinite(d).any() else 0.0
    return off


def predict_coefficients(model: IdentifiedModel, fd: pd.DataFrame, vehicle: Vehicle, span: np.ndarray,
                         bias: str) -> tuple[pd.DataFrame, tuple[FitMetric, ...]]:
    """Each channel's coefficient from the flight data's regressors, on rows span >= 0;
    with a bias treatment other than none, a mean offset per span is removed (for a
    linear model that is re-estimating its intercept)."""
    sig = vehicle_signals(fd, vehicle)
    frame = {"t_s": fd["t_s"].to_numpy(float), "span": span}
    metrics = []
    use = span >= 0
    for ch in model.channels:
        meas = np.where(use, fd[ch].to_numpy(float), np.nan)
        pred = np.where(use, np.broadcast_to(model.evaluate(ch, sig), len(fd)), np.nan)
        off = _offset_per_span(meas, pred, span) if bias != "none" else np.zeros(len(fd))
        frame[f"measured_{ch}"], frame[f"predicted_{ch}"] = meas, pred + off
        m = fit_metric(ch, "-", meas, pred + off, float(np.nanmean(off[use])) if bias != "none" and use.any()
                       else float("nan"), "EBM flight data")
        metrics.append(m)
    return pd.DataFrame(frame), tuple(metrics)


def attitude_on(raw: pd.DataFrame, t_s: np.ndarray, source: str):
    """(phi, theta) [rad] of the raw telemetry's optional attitude columns on t_s, or None
    when a column is missing; ValueError naming the column when it cannot be radians."""
    if not all(c in raw.columns for c in ATTITUDE_COLUMNS):
        return None
    out = []
    t_raw = raw["t_s"].to_numpy(float)
    for col, lim in zip(ATTITUDE_COLUMNS, (math.pi * 1.0001, math.pi / 2 * 1.0001)):
        x = raw[col].to_numpy(float)
        ok = np.isfinite(x)
        if ok.sum() < 2:
            raise ValueError(f"{source}: column {col!r} has {int(ok.sum())} finite values: no attitude")
        bad = np.flatnonzero(ok & (np.abs(x) > lim))
        if bad.size:
            raise ValueError(f"{source}: column {col!r} is outside +-{math.degrees(lim):.0f} deg at rows "
                             f"{bad[:10].tolist()} (max |value| {np.nanmax(np.abs(x)):.3g}): it must be radians")
        out.append(np.interp(t_s, t_raw[ok], x[ok]))
    return tuple(out)


def measured_outputs(pre: pd.DataFrame, fd: pd.DataFrame, vehicle: Vehicle,
                     wideband: bool = False) -> tuple[pd.DataFrame, dict]:
    """The measured outputs on the flight data's rows (from the preprocessed telemetry's
    clean columns) and where each came from.  Without vanes alpha and beta are the flight
    data's (inverted from the force database); wideband: those before the band's low-pass
    (``alpha_wideband_rad``, ``beta_wideband_rad``, when the flight data carry them), as the
    other outputs are (an output-error fit)."""
    t_pre, t = pre["t_s"].to_numpy(float), fd["t_s"].to_numpy(float)
    idx = np.clip(np.searchsorted(t_pre, t - 1e-9), 0, len(t_pre) - 1)
    if not np.allclose(t_pre[idx], t, atol=1e-6, rtol=0):
        raise ValueError("the flight data's times are not on the preprocessed grid")
    cols, src = {}, {}
    for out, col in (("q_rad_s", "q_rad_s"), ("p_rad_s", "p_rad_s"), ("r_rad_s", "r_rad_s"),
                     ("az_m_s2", "az_m_s2"), ("ay_m_s2", "ay_m_s2")):
        cols[out] = pre[f"{col}_clean"].to_numpy(float)[idx]
        src[out] = f"telemetry {col}" + (" (at the accelerometer; the prediction is moved there)"
                                          if col.startswith("a") else "")
    vanes = vehicle.air_data_source == "vanes" and all(f"{c}_clean" in pre for c in (vehicle.alpha_column,
                                                                                     vehicle.beta_column))
    at_cg = dict(zip(("alpha_rad", "beta_rad"), vane_angles(t_pre, pre, vehicle))) if vanes else {}
    moved = ("" if not vehicle.vane_delay_s else f", advanced by the vanes' delay {vehicle.vane_delay_s:g} s") + (
        "" if not any(vehicle.vane_position_m) else f", moved to the CG from {list(vehicle.vane_position_m)} m")
    for out, col, bias in (("alpha_rad", vehicle.alpha_column, vehicle.alpha_bias_rad),
                           ("beta_rad", vehicle.beta_column, vehicle.beta_bias_rad)):
        if vanes:
            cols[out] = at_cg[out][idx] - bias
            src[out] = f"telemetry {col}" + (f" less its calibration bias {bias:g} rad" if bias else "") + moved
        elif wideband and f"{out[:-4]}_wideband_rad" in fd:
            cols[out] = fd[f"{out[:-4]}_wideband_rad"].to_numpy(float)
            src[out] = "EBM flight data before the band's low-pass (from the force-database inversion; no vane)"
        else:
            cols[out] = fd[out].to_numpy(float)
            src[out] = "EBM flight data (from the force-database inversion; no vane)"
    return pd.DataFrame(cols), src


def density_source(raw: pd.DataFrame, fd: pd.DataFrame) -> tuple[str, str | None]:
    """Where the flight data's density came from, and a note when the telemetry's own
    measured density was not what the estimation used."""
    if "rho_kg_m3" not in raw.columns or not np.isfinite(raw["rho_kg_m3"].to_numpy(float)).any():
        return "US-1976 at the recorded altitude (as the estimation; no rho_kg_m3 column)", None
    rho = np.interp(fd["t_s"].to_numpy(float), raw["t_s"].to_numpy(float)[np.isfinite(raw["rho_kg_m3"])],
                    raw["rho_kg_m3"].to_numpy(float)[np.isfinite(raw["rho_kg_m3"])])
    if np.allclose(fd["rho_kg_m3"].to_numpy(float), rho, rtol=5e-3):
        return "measured (telemetry rho_kg_m3), as the estimation", None
    dev = float(np.median(fd["rho_kg_m3"].to_numpy(float) / rho) - 1)
    return ("US-1976 at the recorded altitude, as the estimation",
            f"the telemetry carries a measured density (rho_kg_m3) that the estimation did not use "
            f"(its density is {100 * dev:+.1f} % from it); the prediction follows the estimation so that the "
            "identified coefficients and the dynamic pressure stay consistent")


def choose_axes(model: IdentifiedModel, axes: str) -> tuple[tuple[str, ...], list[str]]:
    """The axes to simulate: auto = lon, plus lat when the model has CY, Cl, Cn all identified."""
    if axes not in AXES_CHOICES:
        raise ValueError(f"unknown axes {axes!r}; choose one of {', '.join(AXES_CHOICES)}")
    notes = []
    have = {ax: all(ch in model.models for ch in AXIS_CHANNELS[ax]) for ax in AXIS_CHANNELS}
    if axes == "auto":
        chosen = [ax for ax in ("lon", "lat") if have[ax]]
        if "lat" in chosen and model.unidentified(AXIS_CHANNELS["lat"]):
            chosen.remove("lat")
            notes.append("lateral axis not simulated: coefficient(s) "
                         f"{model.unidentified(AXIS_CHANNELS['lat'])} were not identifiable (use --axes lat to force)")
        return tuple(chosen), notes
    wanted = ("lon", "lat") if axes == "both" else (axes,)
    for ax in wanted:
        if not have[ax]:
            raise ValueError(f"the model has no {'/'.join(c for c in AXIS_CHANNELS[ax] if c not in model.models)} "
                             f"channel: the {ax} axis cannot be simulated")
    return wanted, notes


# --------------------------------------------------------------------------- the whole check
def estimate_manoeuvre(run_dir, telemetry, model: IdentifiedModel, veh: Vehicle, windows=None,
                       needs_attitude: bool = True, progress=None):
    """A manoeuvre through the run's own estimation (preprocessing and smoothing settings from
    RUN_DIR/run.json), in memory: (raw telemetry, EstimatedFlightData, flight data sorted by
    time, span id per row (-1 outside the model's Mach window or in a stretch shorter than
    MIN_SPAN_S), notes).  needs_attitude: check the attitude columns' units before the
    estimation's minutes, not after ("required": also that they are there); then every column's
    units and signs (aerosid.plausibility.units)."""
    from aerosid.ebm import estimate_flight_data
    from aerosid.plausibility.units import check_units
    from aerosid.preprocess.io import read_raw_parquet
    from aerosid.vehicles.airspeed import as_true_airspeed

    job = read_run_json(run_dir).get("job") or {}
    raw = read_raw_parquet(telemetry)
    if needs_attitude and attitude_on(raw, raw["t_s"].to_numpy(float), str(telemetry)) is None \
            and needs_attitude == "required":
        raise ValueError(f"{telemetry}: no {' / '.join(ATTITUDE_COLUMNS)} columns: the simulation needs the "
                         "attitude for gravity; add the measured roll and pitch attitude [rad] to the telemetry")
    check_units(as_true_airspeed(raw, veh.airspeed_kind)[0], veh, str(telemetry))  # as `aerosid run` checks its own
    est = estimate_flight_data(raw, veh, flight=Path(telemetry).stem, windows=windows,
                               preprocess_params=job.get("preprocess_params") or None,
                               smoothing_options=job.get("smoothing_options") or None,
                               min_segment_s=job.get("min_segment_s"), source=str(telemetry),
                               skip_failed=True, progress=progress)
    if progress is not None:
        progress("predict", 0.0)
    notes = [f"segment {s} of {telemetry} left out: {why}" for s, why in est.failed]
    fd = est.flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    keep = mach_window_mask(fd["mach"].to_numpy(), veh.mach_reference, model.mach_half_width)
    span = spans_of(fd, keep)
    if not (span >= 0).any():
        hw = model.mach_half_width
        raise ValueError(f"{telemetry}: no stretch of at least {MIN_SPAN_S:g} s inside the identification's Mach "
                         f"window {veh.mach_reference:g} +- {hw} (the manoeuvre spans Mach "
                         f"{fd['mach'].min():.3g}..{fd['mach'].max():.3g})")
    return raw, est, fd, span, notes


def validate(run_dir: str | Path, telemetry: str | Path, *, vehicle: str | None = None, version: str | None = None,
             bias: str = "offsets", axes: str = "auto", windows=None, progress=None,
             coefficients: str | Path | None = None) -> ValidationResult:
    """Predict the manoeuvre in `telemetry` with RUN_DIR's identified model (the latest
    model version, or `version`, or the coefficients table `coefficients`, e.g. ``aerosid
    refine``'s).  vehicle: the other manoeuvre's vehicle file (default: the run's); windows:
    time windows [s] of the other telemetry, as `aerosid run --window`; progress: an optional
    callback progress(stage, fraction) (the CLI's display)."""
    from aerosid.identification.identified import load_model_file
    from aerosid.vehicles.vehicle import load_vehicle

    if bias not in BIAS_MODES:
        raise ValueError(f"unknown bias treatment {bias!r}; choose one of {', '.join(BIAS_MODES)}")
    if coefficients is not None and version is not None:
        raise ValueError("give a model version or a coefficients file, not both")
    model = load_model_file(coefficients, run_dir) if coefficients is not None else load_identified_model(run_dir,
                                                                                                          version)
    veh = load_vehicle(vehicle or model.vehicle)
    # auto: lat only when its channels were identified (seed-rlv's open-loop lateral replay drifts even
    # with the true model, docs/validation.md); the simulation's model has the identity channels
    # (inverted angles) at the preflight database's values
    chosen, notes = choose_axes(model, axes)
    sim_model, pre_notes = with_preflight_identities(model, veh)
    raw, est, fd, span, more = estimate_manoeuvre(run_dir, telemetry, model, veh, windows, bool(chosen), progress)
    notes += more
    use = span >= 0
    coef_frame, coef_metrics = predict_coefficients(model, fd, veh, span, bias)
    rho_src, rho_note = density_source(raw, fd)
    sources = {"density": rho_src}
    notes += [rho_note] if rho_note else []
    out_metrics, preds, intercepts = [], [], {}
    att = attitude_on(raw, fd["t_s"].to_numpy(float), str(telemetry)) if chosen else None
    if chosen and att is None:
        notes.append("no output prediction: the gravity terms need the attitude, and the telemetry has no "
                     f"{' / '.join(ATTITUDE_COLUMNS)} columns (the EBM's 21-state model carries no attitude); "
                     "add the measured roll and pitch attitude [rad] to the telemetry")
        sources["attitude"] = "missing"
        chosen = ()
    elif chosen:
        sources["attitude"] = f"telemetry {' and '.join(ATTITUDE_COLUMNS)}"
        notes += pre_notes
    if chosen:
        inputs = prediction_inputs(fd, veh, att[0], att[1], span)
        meas, meas_src = measured_outputs(est.preprocessed.frame, fd, veh)
        for ax in chosen:
            pr, metrics, more = scored_axis(sim_model, inputs, meas, meas_src, veh, ax, bias, use)
            preds.append(pr)
            intercepts.update(pr.intercepts)
            notes += more
            out_metrics += metrics
    worse = [m.name for m in out_metrics if m.nrms > 1]
    if worse:
        notes.append(f"{', '.join(worse)}: predicted worse than the measured mean (RMS error > std): the model "
                     "does not describe this motion of this manoeuvre (an axis it was not identified on?)")
    mach = fd["mach"].to_numpy()[use]
    return ValidationResult(str(run_dir), str(telemetry), model, veh.name, bias,
                            (float(mach.min()), float(mach.max())), len(fd), int(use.sum()), coef_metrics,
                            tuple(out_metrics), coef_frame, tuple(preds), intercepts, sources, tuple(notes))


def scored_axis(model: IdentifiedModel, inputs: pd.DataFrame, meas: pd.DataFrame, meas_src: dict, veh: Vehicle,
                axis: str, bias: str, use: np.ndarray) -> tuple:
    """One axis simulated (predict_axis) and scored on the rows `use`: (the AxisPrediction, a
    FitMetric per output, notes: unidentified coefficients counted as 0, then the prediction's)."""
    notes = []
    bad = model.unidentified(AXIS_CHANNELS[axis])
    if bad:
        notes.append(f"{axis} simulation: coefficient(s) {bad} were not identifiable in the run and count as 0")
    pr = predict_axis(model, inputs, meas, veh, axis, bias)
    f = pr.frame
    metrics = []
    for o in AXIS_OUTPUTS[axis]:
        off = float(np.nanmean(f[f"offset_{o}"][use])) if bias != "none" else float("nan")
        metrics.append(fit_metric(o, OUTPUT_UNITS[o], f[f"measured_{o}"][use], f[f"predicted_{o}"][use], off,
                                  meas_src[o]))
    return pr, metrics, notes + list(pr.notes)


def compare_versions(run_dir: str | Path, telemetry: str | Path, versions, *, bias: str = "offsets",
                     windows=None, progress=None) -> pd.DataFrame:
    """Each model version of RUN_DIR simulated on the manoeuvre in `telemetry` (:func:`validate`'s
    longitudinal output prediction): one row per version with ``version``, ``mach_half_width``,
    ``notes`` and, per output, ``<output>_rms`` [its unit], ``<output>_tic`` [-] and ``<output>_n``
    (the samples scored: a simulation that left the envelope scores fewer).  The manoeuvre is
    estimated once (its estimation does not depend on the model).  The simulation integrates a
    model's error over the manoeuvre, so two look-alike terms that lower the equation-error
    residual alike can predict the outputs differently (bench/results/lookalike_simulation.md).
    progress: an optional callback progress(stage, fraction)."""
    from aerosid.vehicles.vehicle import load_vehicle

    if bias not in BIAS_MODES:
        raise ValueError(f"unknown bias treatment {bias!r}; choose one of {', '.join(BIAS_MODES)}")
    versions = list(versions)
    if not versions:
        raise ValueError(f"{run_dir}: no model version to simulate")
    models = {v: load_identified_model(run_dir, v) for v in versions}
    first = models[versions[0]]
    veh = load_vehicle(first.vehicle)
    raw, est, fd, _, notes = estimate_manoeuvre(run_dir, telemetry, first, veh, windows, "required", progress)
    att = attitude_on(raw, fd["t_s"].to_numpy(float), str(telemetry))
    meas, meas_src = measured_outputs(est.preprocessed.frame, fd, veh)
    rows = []
    for k, v in enumerate(versions):
        if progress is not None:
            progress(f"simulate {v}", k / len(versions))
        model = models[v]
        span = spans_of(fd, mach_window_mask(fd["mach"].to_numpy(), veh.mach_reference, model.mach_half_width))
        use = span >= 0
        sim_model, _ = with_preflight_identities(model, veh)
        inputs = prediction_inputs(fd, veh, att[0], att[1], span)
        _, metrics, more = scored_axis(sim_model, inputs, meas, meas_src, veh, "lon", bias, use)
        row = {"version": v, "mach_half_width": model.mach_half_width, "notes": " | ".join(notes + more)}
        for m in metrics:
            row[f"{m.name}_rms"], row[f"{m.name}_tic"], row[f"{m.name}_n"] = m.rms, m.tic, m.n
        rows.append(row)
    if progress is not None:
        progress("done", 1.0)
    return pd.DataFrame(rows)


def version_comparison_text(frame: pd.DataFrame, telemetry, changes: dict | None = None) -> str:
    """compare_versions' frame as a table: RMS per simulated output (angles in deg, rates in
    deg/s), * = the lowest; `changes`: version -> what it changed (printed after it)."""
    outs = [c[:-4] for c in frame.columns if c.endswith("_rms")]
    lines = [f"simulated on {telemetry} (aerosid validate's longitudinal output prediction, output offsets; RMS "
             "of simulated - measured, lower is better, * = lowest among the versions scored on all samples)"]
    unit = {"rad": ("deg", math.degrees(1.0)), "rad/s": ("deg/s", math.degrees(1.0))}
    heads, scales = [], []
    for o in outs:
        u, k = unit.get(OUTPUT_UNITS.get(o, ""), (OUTPUT_UNITS.get(o, ""), 1.0))
        heads.append(f"{o.split('_')[0]} [{u}]")  # alpha_rad -> alpha, q_rad_s -> q, az_m_s2 -> az
        scales.append(k)
    lines.append(f"  {'version':<9}" + "".join(f"{h:>18}" for h in heads) + "  changes")
    # a version whose simulation left the envelope is scored on fewer samples: not comparable, no star
    full = {o: frame[f"{o}_n"] == frame[f"{o}_n"].max() for o in outs}
    best = {o: frame.loc[full[o], f"{o}_rms"].min() for o in outs}
    for i, r in frame.iterrows():
        cells = "".join(f"{r[f'{o}_rms'] * k:>17.4g}{'*' if full[o][i] and r[f'{o}_rms'] == best[o] else ' '}"
                        for o, k in zip(outs, scales))
        lines.append(f"  {r['version']:<9}{cells}  {(changes or {}).get(r['version'], '')}")
    if "mach_half_width" in frame and frame["mach_half_width"].astype(str).nunique() > 1:
        lines.append("  note: the versions were fitted on different Mach windows (--mach-half-width), so each is "
                     "scored on its own samples")
    for _, r in frame.iterrows():
        if r.get("notes"):
            lines.append(f"  note ({r['version']}): {r['notes']}")
    return "\n".join(lines)


def write_validation(result: ValidationResult, out_dir: str | Path) -> dict[str, Path]:
    """validation.json, validation.parquet (time histories) and validation.html, atomically."""
    from aerosid.identification.validation_report import build_validation_report
    from aerosid.io import write_json_atomic, write_parquet_atomic, write_text_atomic

    out = Path(out_dir)
    frame = result.coefficient_frame.copy()
    for pr in result.predictions:
        for c in pr.frame.columns:
            if c not in ("t_s", "span"):
                frame[c] = pr.frame[c].to_numpy()
    return {
        "json": write_json_atomic(result.to_json(), out / "validation.json"),
        "parquet": write_parquet_atomic(frame, out / "validation.parquet",
                                        metadata={"aerosid.kind": "validation", "aerosid.model": result.model.source}),
        "html": write_text_atomic(build_validation_report(result), out / "validation.html"),
    }
