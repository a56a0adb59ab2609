"""``aerosid design``: the manoeuvre that would show what a flight could not (issue 20).

From a run (its flight data, vehicle file and current model) and a target term — a
candidate effect (``pitch_damping``), a coefficient of the model (``Cm_alpha_dot``) or
a model-spec term (``"Cm_a3 = alpha**3"``), optionally ``versus`` a second one — it

1. refits the target's channel on the run (target term added when missing) and keeps
   the residual's windowed autocovariance: the run's noise (predict.ResidualModel);
2. flies candidate inputs noise-free (flyers): 3-2-1-1s and doublets at several time
   units and Schroeder multisines in several bands, each at the largest amplitude the
   vehicle's limits allow (surface deflection and rate, alpha, load factor; limits.py);
3. predicts, for each, the coefficient's σ the pipeline would report (the same
   Morelli-Klein formula with the candidate's regressors and the run's residual) and
   the diagnosis's detectable size ``t(p = 0.001, dof_eff) σ``;
4. flies the best candidate in full, checks the limits on that flight, and says whether
   the effect of the requested size becomes detectable (at 90 % power:
   ``|size| >= (t_crit + z_0.9) σ``), or that no candidate within the limits can, with
   the numbers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.design.flyers import default_flyer
from aerosid.design.limits import Limits, read_limits
from aerosid.design.power import POWER_SETTINGS, power_hint
from aerosid.design.predict import POWER, Prediction, ResidualModel, predict_covariance
from aerosid.design.verdict import design_verdict
from aerosid.design.waveforms import Waveform, candidate_waveforms
from aerosid.identification.band import segment_keys

G = 9.80665


class DesignError(ValueError):
    """A design request that cannot be served; the message says why."""


@dataclass(frozen=True)
class Evaluation:
    waveform: Waveform
    amplitude_rad: float
    prediction: Prediction
    limit_use: dict
    score: float
    model_error_pct: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Design:
    run_dir: str
    channel: str
    targets: tuple[str, ...]
    sizes: tuple[float, ...]
    model_terms: tuple[str, ...]
    before: dict
    after: dict
    waveform: dict
    limits: dict
    limit_use: dict
    achievable: bool
    verdict: str
    candidates: tuple[dict, ...]
    input: pd.DataFrame = field(repr=False)
    notes: tuple[str, ...] = ()

    def to_json(self) -> dict:
        return {"run_dir": self.run_dir, "channel": self.channel, "targets": list(self.targets),
                "sizes": list(self.sizes), "model_terms": list(self.model_terms), "before": self.before,
                "after": self.after, "manoeuvre": self.waveform, "limits": self.limits,
                "limit_use": self.limit_use, "achievable": self.achievable, "verdict": self.verdict,
                "candidates": list(self.candidates), "notes": list(self.notes),
                "method": ("predicted sigma = Morelli-Klein coloured-residual covariance of the candidate's "
                           "noise-free regressors under the run's windowed residual autocovariance; detectable "
                           "size = t(p=0.001, dof_eff) x sigma (the diagnosis's); reliable size = "
                           f"(t_crit + z_{POWER:g}) x sigma")}

    def summary(self) -> str:
        lines = [f"design for {', '.join(self.targets)} ({self.channel}) on {self.run_dir}",
                 f"  manoeuvre: {self.waveform['label']}, amplitude {self.waveform['amplitude_rad']:.4g} rad "
                 f"({math.degrees(self.waveform['amplitude_rad']):.2f} deg), {self.waveform['start_s']:.1f}-"
                 f"{self.waveform['end_s']:.1f} s"]
        for name, size in zip(self.targets, self.sizes):
            b, a = self.before[name], self.after[name]
            lines.append(f"  {name} (size {size:.4g}): sigma {b['sigma']:.4g} -> {a['sigma']:.4g}, detectable size "
                         f"{b['detectable_size']:.4g} -> {a['detectable_size']:.4g}, found at 90 % "
                         f"{b['reliable_size']:.4g} -> {a['reliable_size']:.4g}")
        if len(self.targets) == 2:
            lines.append(f"  correlation of the two estimates: {self.before['correlation']:.3f} -> "
                         f"{self.after['correlation']:.3f}")
        u = self.limit_use
        lines.append(f"  limits used: surface {100 * u['surface']:.0f} %, rate {100 * u['surface_rate']:.0f} %, "
                     f"alpha {100 * u['alpha']:.0f} %, load factor {100 * u['load_factor']:.0f} %")
        lines.append("  " + self.verdict)
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


# ----------------------------------------------------------------------------- targets
def resolve_term(text: str, models: dict, vehicle):
    """(channel, Term) for a candidate name, a model coefficient or 'NAME = EXPR' ('Cm: NAME = EXPR')."""
    from aerosid.diagnosis.candidates import default_candidates
    from aerosid.modelling.models import ModelSpecError, Term, parse_term

    text = text.strip()
    for c in default_candidates(vehicle.mach_reference, vehicle.vehicle_class):
        if c.name == text:
            return c.channel, Term(c.coefficient, c.term, c.name if c.catalogue else None)
    for ch, m in models.items():
        for t in m.terms:
            if text in (t.coefficient, t.effect):
                return ch, t
    for c in default_candidates(vehicle.mach_reference, vehicle.vehicle_class):
        if c.coefficient == text:
            return c.channel, Term(c.coefficient, c.term, c.name if c.catalogue else None)
    if "=" in text:
        ch, _, rest = text.partition(":") if ":" in text.split("=")[0] else ("Cm", "", text)
        ch = ch.strip()
        if ch not in models:
            raise DesignError(f"channel {ch!r} is not in the run's models ({', '.join(models)})")
        try:
            return ch, parse_term(rest or text, ch)
        except ModelSpecError as exc:
            raise DesignError(str(exc)) from exc
    raise DesignError(f"unknown effect or term {text!r}: give a candidate effect (aerosid simulate --list-effects, "
                      "alpha_dot, ...), a coefficient of the run's model, or 'CHANNEL: NAME = EXPRESSION'")


def _signals_from_truth(truth: pd.DataFrame, vehicle) -> dict:
    from aerosid.diagnosis.candidates import derived_signals
    from aerosid.diagnosis.synthetic import NO_NOISE, flight_data_from_truth
    from aerosid.modelling.models import vehicle_signals

    fd = flight_data_from_truth(truth, NO_NOISE)
    return derived_signals(vehicle_signals(fd, vehicle), vehicle.length_pitch_m, vehicle.length_lateral_m)


def _max_amplitude(base: np.ndarray, d: np.ndarray, lo: float, hi: float) -> float:
    """Largest A >= 0 with lo <= base + A d <= hi on every sample."""
    # a limit the flight breaks without the input (e.g. a lateral step) is not the input's to keep
    lo, hi = np.minimum(lo, base), np.maximum(hi, base)
    a = np.inf
    pos, neg = d > 1e-12 * max(1.0, float(np.max(np.abs(d)))), d < -1e-12 * max(1.0, float(np.max(np.abs(d))))
    if pos.any():
        a = min(a, float(np.min((hi[pos] - base[pos]) / d[pos])))
    if neg.any():
        a = min(a, float(np.min((lo[neg] - base[neg]) / d[neg])))
    return max(a, 0.0)


def _limit_amplitude(base: pd.DataFrame, unit: pd.DataFrame, limits: Limits, dt: float) -> float:
    """Largest amplitude keeping surfaces, surface rates, alpha and load factor within limits
    (linear in the amplitude: base + A (unit - base))."""
    amax = np.inf
    for i, (lo, hi) in enumerate(limits.surface_rad):
        c = f"d{i + 1}_rad"
        b, d = base[c].to_numpy(float), unit[c].to_numpy(float) - base[c].to_numpy(float)
        k = 1.0 - limits.margin
        amax = min(amax, _max_amplitude(b, d, lo * k, hi * k))
        r = limits.surface_rate_rad_s
        amax = min(amax, _max_amplitude(np.diff(b) / dt, np.diff(d) / dt, -r, r))
    b, d = base["alpha_rad"].to_numpy(float), unit["alpha_rad"].to_numpy(float) - base["alpha_rad"].to_numpy(float)
    amax = min(amax, _max_amplitude(b, d, *limits.alpha_rad))
    nb, nd = -base["az_cg_m_s2"].to_numpy(float) / G, -(unit["az_cg_m_s2"] - base["az_cg_m_s2"]).to_numpy(float) / G
    amax = min(amax, _max_amplitude(nb, nd, *limits.load_factor))
    return float(amax)


def _scaled(base: pd.DataFrame, unit: pd.DataFrame, a: float, cols) -> pd.DataFrame:
    out = base.copy()
    for c in cols:
        out[c] = base[c].to_numpy(float) + a * (unit[c].to_numpy(float) - base[c].to_numpy(float))
    return out


def _use(truth: pd.DataFrame, limits: Limits, dt: float, mask: np.ndarray | None = None) -> dict:
    s = truth[[f"d{i}_rad" for i in range(1, 5)]].to_numpy(float)
    return limits.check(s, truth["alpha_rad"].to_numpy(float), -truth["az_cg_m_s2"].to_numpy(float) / G, dt)


# ----------------------------------------------------------------------------- design
def design(run_dir: str | Path, effect: str, size: float | None = None, versus: str | None = None, *,
           versus_size: float | None = None, mach_half_width: float = 0.5,
           kinds: tuple[str, ...] = ("3211", "doublet", "multisine"),
           refine: bool = True, progress=None, flyer_factory=None, power: str = "trim") -> Design:
    from aerosid.diagnosis.candidates import derived_signals
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.models import vehicle_signals
    from aerosid.identification.regression import fit_linear
    from aerosid.vehicles.vehicle import load_vehicle
    from aerosid.modelling.versions import latest_models, read_flight_data, run_vehicle

    say = progress or (lambda msg: None)
    if power not in POWER_SETTINGS:
        raise DesignError(f"unknown power setting {power!r}; choices: {', '.join(POWER_SETTINGS)}")
    run_dir = Path(run_dir)
    vref = run_vehicle(run_dir)
    vehicle = load_vehicle(vref)
    limits = read_limits(vref)
    models = latest_models(run_dir)
    if versus_size is not None and not versus:
        raise DesignError("--versus-size needs --versus (the size of the second term)")
    for name, val in (("--size", size), ("--versus-size", versus_size)):
        if val is not None and not (math.isfinite(val) and val != 0.0):
            raise DesignError(f"{name} {val!r}: a size must be a finite, non-zero coefficient value")
    ch, term = resolve_term(effect, models, vehicle)
    terms = [term]
    if versus:
        ch2, term2 = resolve_term(versus, models, vehicle)
        if ch2 != ch:
            raise DesignError(f"{effect} is a {ch} term and {versus} a {ch2} term: they cannot be confused")
        terms.append(term2)
    model = models[ch]
    for t in terms:
        model = model.with_term(t)
    targets = tuple(t.coefficient for t in terms)
    if len(set(targets)) < len(targets):
        raise DesignError(f"{effect} and {versus} are the same term")

    # ---- the run: its fit and its residual
    fd = read_flight_data(run_dir).sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    fd = fd.loc[mach_window_mask(fd["mach"].to_numpy(float), vehicle.mach_reference, mach_half_width)]
    fd = fd.reset_index(drop=True)
    groups = segment_keys(fd)
    sig = derived_signals(vehicle_signals(fd, vehicle), vehicle.length_pitch_m, vehicle.length_lateral_m)
    X, _ = model.design(sig)
    fit = fit_linear(fd[ch].to_numpy(float), X, names=model.names, channel=ch, groups=groups)
    fs = 1.0 / float(np.median(np.diff(fd["t_s"].to_numpy(float))))
    resid = ResidualModel.from_residual(np.asarray(fit.residuals), fs, groups=groups, max_lag=fit.max_lag)
    before_pred = predict_covariance(X.to_numpy(float), model.names, resid)
    estimates = dict(zip(model.names, np.asarray(fit.estimate, float)))
    sizes = []
    from aerosid.modelling.effects import CATALOGUE

    # the size each target is to be found at: given; else, one target: the catalogue's physical
    # default, else the run's estimate; two targets (--versus): a term the run's model already has
    # takes the run's estimate, a term the design adds the catalogue's size (the absent one of two
    # look-alikes has an estimate near zero in the joint fit), else the run's estimate
    in_run = set(models[ch].names)
    for i, t in enumerate(targets):
        given = size if i == 0 else versus_size
        est = estimates.get(t, np.nan)
        has_est = bool(np.isfinite(est) and est != 0.0)
        if given is not None:
            sizes.append(float(given))
        elif versus and t in in_run and has_est:
            sizes.append(float(est))
        elif terms[i].effect in CATALOGUE:
            sizes.append(float(CATALOGUE[terms[i].effect].value))
        elif has_est:
            sizes.append(float(est))
        else:
            raise DesignError(f"no size for {t}: give {'--size' if i == 0 else '--versus-size'}")
    sizes = tuple(sizes)

    def summarise(pred: Prediction, reported: Prediction | None = None) -> dict:
        out = {}
        for t in targets:
            out[t] = {"sigma": pred.sigma(t), "detectable_size": pred.detectable_size(t),
                      "reliable_size": pred.reliable_size(t), "n_eff": pred.n_eff, "dof_eff": pred.dof_eff}
        if len(targets) == 2:
            out["correlation"] = pred.correlation(*targets)
        return out

    before = summarise(before_pred)
    for t in targets:  # what the run's own fit reported (equal to the prediction by construction)
        j = model.names.index(t)
        before[t]["sigma_reported"] = float(fit.std_error[j])
        before[t]["estimate"] = float(fit.estimate[j])

    def score(pred: Prediction, bias: dict | None = None) -> float:
        """max over the targets of 2 sigma / |size| + |model error| (the model structure's own error on
        the shape, when the simulator states its truth: a separation that the model cannot fit is none)."""
        bias = bias or {}
        return max(2.0 * pred.sigma(t) / abs(s) + abs(bias.get(t, 0.0)) / 100.0 for t, s in zip(targets, sizes))

    # ---- the flyer
    notes = list(limits.assumed and [f"assumed limit: {a}" for a in limits.assumed])
    coefs = dict(zip(fit.names, np.asarray(fit.estimate, float))) if ch == "Cm" else {}
    if flyer_factory is None:
        flyer, base, start, end, linear = default_flyer(vehicle, limits, coefs, terms[0].effect, sizes[0], say,
                                                        power=power)
    else:
        flyer, base, start, end, linear = flyer_factory(vehicle, limits, coefs, terms[0].effect, sizes[0], say)
    in_win = mach_window_mask(base["mach"].to_numpy(float), vehicle.mach_reference, mach_half_width)
    dt = flyer.dt
    t = flyer.t
    # input ramps: a full-travel step would take max_surface / rate; at least 0.2 s, at most 0.6 s
    ramp = float(np.clip(max(hi for _, hi in limits.surface_rad) / limits.surface_rate_rad_s, 0.2, 0.6))
    cands = [w for w in candidate_waveforms(t, start, end, ramp) if w.kind in kinds]
    cols = [c for c in base.columns if c not in ("t_s",) and base[c].dtype.kind == "f"]
    evals: list[Evaluation] = []
    a_ref = getattr(flyer, "reference_rad", 0.08)  # the elevator amplitude the shapes are flown at
    for k, w in enumerate(cands):
        say(f"candidate {k + 1}/{len(cands)}: {w.label()}")
        unit = flyer.linear_response(w.values) if linear else flyer.fly(a_ref * w.values)
        bias = {}
        if not linear:  # the model's own error on this shape (at a_ref), then per unit amplitude
            mk = mach_window_mask(unit["mach"].to_numpy(float), vehicle.mach_reference, mach_half_width)
            bias = _oracle(unit, _signals_from_truth(unit, vehicle), mk, model, ch, targets,
                           getattr(flyer, "coefficients", None))
            unit = _scaled(base, unit, 1.0 / a_ref, cols)
        a = _limit_amplitude(base, unit, limits, dt)
        if not np.isfinite(a) or a <= 0:
            continue
        tr = _scaled(base, unit, a, cols)
        s = _signals_from_truth(tr, vehicle)
        Xc, _ = model.design({kk: np.asarray(v)[in_win] if np.ndim(v) else v for kk, v in s.items()})
        pred = predict_covariance(Xc.to_numpy(float), model.names, resid)
        evals.append(Evaluation(w, a, pred, _use(tr, limits, dt), score(pred, bias), bias))
    if not evals:
        raise DesignError("no candidate input moves the vehicle within its limits")
    evals.sort(key=lambda e: e.score)

    # ---- fly the best in full (back off if the full flight breaks a limit)
    best = evals[0]
    a = best.amplitude_rad
    # a limit the flight already uses beyond 1 without the designed input (the lateral doublets of a
    # generated JSBSim design against an assumed rate limit) is not the input's to keep: the full
    # flight may use each limit up to what the baseline already uses (whole-flight maxima: a coarser
    # rule than _max_amplitude's per sample, which sized the candidate; the loop only catches the
    # full flight's non-linear overshoot)
    base_use = _use(base, limits, dt)
    keys = ("surface", "surface_rate", "alpha", "load_factor")
    for _ in range(4):
        say(f"flying the chosen design in full: {best.waveform.label()}, amplitude {a:.4g} rad")
        tr = flyer.fly(a * best.waveform.values)
        use = _use(tr, limits, dt)
        worst = max(use[k] / max(1.0, base_use[k]) for k in keys)
        if worst <= 1.0 + 1e-9:
            break
        a *= 0.97 / worst
    notes += [f"the flight without the designed input already uses the {k.replace('_', ' ')} limit at "
              f"{100 * base_use[k]:.0f} % (its other axes' inputs); the design adds nothing beyond it"
              for k in keys if base_use[k] > 1.0]
    in_win_full = mach_window_mask(tr["mach"].to_numpy(float), vehicle.mach_reference, mach_half_width)
    s = _signals_from_truth(tr, vehicle)
    Xf, _ = model.design({kk: np.asarray(v)[in_win_full] if np.ndim(v) else v for kk, v in s.items()})
    oracle = _oracle(tr, s, in_win_full, model, ch, targets, getattr(flyer, "coefficients", None))
    if oracle:
        notes.append("model error on this manoeuvre (the model fitted to the simulator's noise-free flight as the "
                     "sensors see it, true regressors): " + ", ".join(f"{t} {v:+.1f} %" for t, v in oracle.items()))
    after_run = predict_covariance(Xf.to_numpy(float), model.names, resid)
    after_pred = after_run
    if refine:
        # the estimation error itself depends on the manoeuvre (the smoother's process noise
        # follows the flight's spectrum): fly the design once with the sensors' noise and
        # faults through the pipeline and take that flight's residual instead of the run's
        say("flying the design once with sensor noise through the pipeline (the new flight's residual)")
        resid_new, X_new = _pipeline_residual(flyer.noisy(a * best.waveform.values, REFINE_SEED), vehicle, model,
                                              ch, mach_half_width)
        after_pred = predict_covariance(X_new, model.names, resid_new)
        notes.append(f"sigma after = the pipeline's on one noisy simulated flight of the design (seed "
                     f"{REFINE_SEED}: its estimated regressors and its residual, rms {math.sqrt(resid_new.variance):.3g}"
                     f" vs the run's {math.sqrt(resid.variance):.3g}); the noise-free regressors with the run's "
                     "residual predict " + ", ".join(f"{t} {after_run.sigma(t):.3g}" for t in targets))
    after = summarise(after_pred)
    after["noise_free_run_residual"] = summarise(after_run)

    t_run = len(fd) / fs
    t_design = (np.shape(X_new)[0] if refine else int(np.sum(in_win_full))) * dt
    ok, verdict = design_verdict(targets, sizes, before, after, after_pred, oracle, best.waveform.label(), a,
                                 worst, hint=lambda rel: power_hint(oracle, rel, power, flyer),
                                 time_ratio=t_design / t_run if t_run > 0 else 1.0)
    u = np.asarray(a * best.waveform.values)
    table = pd.DataFrame({"t_s": t, flyer.column: u})
    if getattr(flyer, "extra", None) is not None:
        for c in flyer.extra.columns:
            if c != "t_s":
                table[c] = flyer.extra[c].to_numpy(float)
    if getattr(flyer, "throttle", None) is not None:  # a fixed-throttle glide (--power idle)
        table["throttle_cmd_norm"] = float(flyer.throttle)
    w = best.waveform
    wave = {"kind": w.kind, "label": w.label(), "time_unit_s": w.time_unit_s, "band_hz": list(w.band_hz),
            "amplitude_rad": float(a), "start_s": w.start_s, "end_s": w.end_s, "duration_s": float(t[-1]),
            "ramp_s": ramp, "column": flyer.column, "power": power,
            "throttle_cmd_norm": getattr(flyer, "throttle", None)}
    cand_rows = tuple({"label": e.waveform.label(), "amplitude_rad": e.amplitude_rad,
                       **{f"sigma_{tt}": e.prediction.sigma(tt) for tt in targets},
                       **{f"model_error_pct_{tt}": v for tt, v in e.model_error_pct.items()},
                       "binding_limit": max(("surface", "surface_rate", "alpha", "load_factor"),
                                            key=lambda kk: e.limit_use[kk])} for e in evals[:12])
    if linear:
        notes.append("candidates ranked on the simulator linearised about a flight without pitch manoeuvres; the "
                     "chosen one flown in full (the 'after' numbers)")
    if not refine:
        notes.append("sigma assumes the run's residual (estimation error) carries over to the new flight; larger "
                     "manoeuvres can raise it (the smoother's band follows the flight's spectrum)")
    if oracle:
        after["model_error_pct"] = oracle
    return Design(str(run_dir), ch, targets, sizes, model.names, before, after, wave, limits.to_dict(), use, ok,
                  verdict, cand_rows, table, tuple(notes))


REFINE_SEED = 987654


def _oracle(truth: pd.DataFrame, signals: dict, mask: np.ndarray, model, ch: str, targets, coefficients) -> dict:
    """% error of the targets when the model is fitted to the simulator's noise-free flight as the
    sensors see it (the channel plus a propulsive part, `<ch>_prop`, when the truth has one) with the
    true regressors: the model structure's own error on this manoeuvre.  Empty when the simulator
    does not state its true coefficients."""
    if not coefficients or not all(t in coefficients for t in targets):
        return {}
    y = truth[ch].to_numpy(float) + (truth[f"{ch}_prop"].to_numpy(float) if f"{ch}_prop" in truth else 0.0)
    X, _ = model.design({k: np.asarray(v)[mask] if np.ndim(v) else v for k, v in signals.items()})
    A = X.to_numpy(float)
    y = y[mask]
    ok = np.isfinite(y) & np.all(np.isfinite(A), axis=1)
    th = np.linalg.lstsq(A[ok], y[ok], rcond=None)[0]
    est = dict(zip(model.names, th))
    return {t: float(100.0 * (est[t] / coefficients[t] - 1.0)) for t in targets if coefficients[t] != 0}


def _pipeline_residual(telemetry: pd.DataFrame, vehicle, model, ch: str, mach_half_width: float) -> ResidualModel:
    """The channel residual of the pipeline on a simulated noisy flight (process_telemetry)."""
    import warnings

    from aerosid.diagnosis.candidates import derived_signals
    from aerosid.ebm import process_telemetry
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.models import vehicle_signals
    from aerosid.identification.regression import fit_linear

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = process_telemetry(telemetry, vehicle, mach_half_width=mach_half_width)
    fd = run.flight_data.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    fd = fd.loc[mach_window_mask(fd["mach"].to_numpy(float), vehicle.mach_reference, mach_half_width)]
    fd = fd.reset_index(drop=True)
    groups = segment_keys(fd)
    sig = derived_signals(vehicle_signals(fd, vehicle), vehicle.length_pitch_m, vehicle.length_lateral_m)
    X, _ = model.design(sig)
    y = fd[ch].to_numpy(float)
    ok = np.isfinite(y) & np.all(np.isfinite(X.to_numpy(float)), axis=1)
    X, y, groups = X.loc[ok], y[ok], groups[ok]
    fit = fit_linear(y, X, names=model.names, channel=ch, groups=groups)
    fs = 1.0 / float(np.median(np.diff(fd["t_s"].to_numpy(float))))
    return (ResidualModel.from_residual(np.asarray(fit.residuals), fs, groups=groups, max_lag=fit.max_lag),
            X.to_numpy(float))


def write_design(d: Design, out_dir: str | Path) -> dict[str, Path]:
    from aerosid.design.io import write_input
    from aerosid.io import write_json_atomic

    paths = write_input(d.input, out_dir, {"aerosid.design.targets": ",".join(d.targets)})
    paths["json"] = write_json_atomic(d.to_json(), Path(out_dir) / "design.json")
    return paths
