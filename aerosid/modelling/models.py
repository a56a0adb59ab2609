"""Model specifications: which terms each channel's linear model holds.

A term is ``NAME = EXPRESSION`` (expression in ``aerosid.modelling.expressions`` over the
signals below) or the bare name of a catalogue effect (``pitch_damping``), which
brings its own coefficient name and term.  The defaults are method.md §11.

Spec files are TOML, one table per channel::

    [Cm]
    terms = ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p/2", "pitch_damping"]

or relative to the parent model, ``add = ["pitch_damping"]`` / ``remove = ["Cm_0"]``
(aerosid.modelling.model_specs).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.identification.derivatives import smooth_derivative
from aerosid.modelling.effects import CATALOGUE
from aerosid.modelling.expressions import BAND_ORDER_KEY, ROW_KEY, ExpressionError, evaluate, parse, signal_names

SIGNALS = ("alpha", "beta", "alpha_r", "phi_r", "mach", "V", "qbar", "delta_p", "delta_y", "delta_r",
           "p", "q", "r", "p_hat", "q_hat", "r_hat", "alpha_dot_hat", "beta_dot_hat", "t",
           "delta_p_dot", "delta_y_dot", "delta_r_dot")
#: Half-length of the Savitzky-Golay window of the fin rates delta_*_dot [s]: the fins are
#: measured with little noise (0.02 deg), and a control lag of tens of ms lives at 1-3 Hz
FIN_RATE_HALF_WINDOW_S = 0.05
CHANNELS = ("CN", "Cm", "CY", "Cn", "Cl")
#: Default half-length of the Savitzky-Golay window of alpha_dot_hat and beta_dot_hat [s]
#: (a vehicle file may set its own: [air_data] derivative_half_window_s)
RATE_HALF_WINDOW_S = 0.25
#: Most terms one channel's model may hold (the default models have 3-6; the regression's
#: cost grows with the square of the count, and 2000 terms took 400 s and 1.5 GB).
MAX_TERMS = 40
#: Largest model specification file read [bytes].
MAX_SPEC_BYTES = 1_000_000


class ModelSpecError(ValueError):
    """A model specification that cannot be used; names the file and the term."""


@dataclass(frozen=True)
class Term:
    coefficient: str
    expression: str
    effect: str | None = None  # the catalogue effect it came from, if any


@dataclass(frozen=True)
class ChannelModel:
    channel: str
    terms: tuple[Term, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(t.coefficient for t in self.terms)

    def regressors(self, signals: dict[str, np.ndarray]) -> pd.DataFrame:
        return self.design(signals)[0]

    def design(self, signals: dict[str, np.ndarray]) -> tuple[pd.DataFrame, tuple[str, ...]]:
        """The regressor columns and a note for every term that is not finite on some
        samples where its signals are (those samples leave the fit).  A term that is
        finite on none of them raises ModelSpecError naming the term and the reason."""
        n = len(signals["alpha"])
        columns, notes = {}, []
        for t in self.terms:
            x = evaluate(t.expression, signals, n)
            inputs_ok = np.ones(n, dtype=bool)
            for name in sorted(signal_names(t.expression, signals)):
                finite = np.isfinite(np.asarray(signals[name], dtype=float))
                if not finite.all():
                    if not finite.any():
                        raise ModelSpecError(f"[{self.channel}] term {t.coefficient} = {t.expression}: its signal "
                                             f"{name!r} has no finite value in the flight data ({n} samples)")
                    notes.append(f"term {t.coefficient} = {t.expression}: signal {name!r} is not finite at "
                                 f"{int((~finite).sum())} of {n} samples: those samples are left out of the "
                                 f"{self.channel} fit")
                inputs_ok &= finite
            bad = inputs_ok & ~np.isfinite(x)
            n_in, n_bad = int(inputs_ok.sum()), int(bad.sum())
            if n_bad:
                what = _nonfinite_kind(x[bad])
                if n_bad == n_in:
                    raise ModelSpecError(f"[{self.channel}] term {t.coefficient} = {t.expression}: {what} at every "
                                         f"one of the {n_in} samples ({_likely_cause(t.expression)}); "
                                         "fix the term or remove it")
                notes.append(f"term {t.coefficient} = {t.expression} is {what} at {n_bad} of {n_in} samples "
                             f"({100.0 * n_bad / n_in:.1f} %; {_likely_cause(t.expression)}): those samples are "
                             f"left out of the {self.channel} fit")
            columns[t.coefficient] = x
        return pd.DataFrame(columns), tuple(notes)

    def with_term(self, term: Term) -> "ChannelModel":
        if term.coefficient in self.names:
            return self
        return ChannelModel(self.channel, self.terms + (term,))


def _nonfinite_kind(x: np.ndarray) -> str:
    kinds = [k for k, m in (("NaN", np.isnan(x)), ("infinite", np.isinf(x))) if m.any()]
    return " or ".join(kinds)


def _likely_cause(expression: str) -> str:
    hints = [h for f, h in (("log", "log of a value <= 0"), ("sqrt", "sqrt of a negative value"),
                            ("/", "division by zero"), ("**", "a power that overflows or of a negative base"),
                            ("exp", "exp overflows"), ("tan", "tan at +-pi/2")) if f in expression]
    return "likely " + " or ".join(hints) if hints else "overflow"


DEFAULT_TERMS = {
    "CN": ["CN_0 = 1", "CN_alpha = alpha", "CN_delta_p = delta_p/2"],
    "Cm": ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p/2"],
    "CY": ["CY_0 = 1", "CY_beta = beta", "CY_delta_y = delta_y/2"],
    "Cn": ["Cn_0 = 1", "Cn_beta = beta", "Cn_delta_y = delta_y/2"],
    "Cl": ["Cl_0 = 1", "Cl_alpha_r = alpha_r", "Cl_cos4phi = cos(4*phi_r)", "Cl_delta_r = delta_r"],
}
#: The aircraft class's default models (the textbook linear aircraft model: c172x's vehicle file and
#: every generated JSBSim vehicle file state them, docs/jsbsim.md), for an aircraft's vehicle file
#: without a [models] table.  Before, such a file got the finned class's models above: no pitch or
#: roll damping, C_l in the roll orientation (c182 by hand: C_m,delta -13.9 %, C_N,delta +36 %, "ok").
AIRCRAFT_TERMS = {
    "CN": ["CN_0 = 1", "CN_alpha = alpha", "CN_delta_p = delta_p", "CN_q = q_hat"],
    "Cm": ["Cm_0 = 1", "Cm_alpha = alpha", "Cm_delta_p = delta_p", "pitch_damping", "Cm_alpha_dot = alpha_dot_hat"],
    "CY": ["CY_0 = 1", "CY_beta = beta", "CY_delta_y = delta_y"],
    "Cl": ["Cl_0 = 1", "Cl_beta = beta", "Cl_p = p_hat", "Cl_r = r_hat", "Cl_delta_r = delta_r", "Cl_delta_y = delta_y"],
    "Cn": ["Cn_0 = 1", "Cn_beta = beta", "Cn_p = p_hat", "Cn_r = r_hat", "Cn_delta_r = delta_r", "Cn_delta_y = delta_y"],
}


def parse_term(text: str, channel: str, source: str = "<memory>", mach_reference: float = 12.4) -> Term:
    """``NAME = EXPR`` or the name of a candidate the diagnosis can report: a catalogue
    effect (``pitch_damping``) or an extra candidate (``mach_cm0``, ``roll_damping``, ...;
    Mach terms about `mach_reference`).  The candidate's channel must match."""
    text = text.strip()
    if "=" not in text:
        effect = CATALOGUE.get(text)
        if effect is not None:
            if effect.channel != channel:
                raise ModelSpecError(f"{source}: [{channel}] effect {text!r} belongs to channel {effect.channel}")
            # Mach terms about the vehicle's reference Mach, as the diagnosis tests them
            return Term(effect.coefficient, effect.term.replace("(mach - 12.4)", f"(mach - {mach_reference:g})"),
                        effect.name)
        from aerosid.diagnosis.candidates import named_candidates  # (a cycle otherwise)

        named = named_candidates(mach_reference)
        cand = named.get(text)
        if cand is None:
            raise ModelSpecError(f"{source}: [{channel}] term {text!r} is neither 'NAME = EXPRESSION' nor the name "
                                 f"of a candidate effect ({', '.join([*CATALOGUE, *named])})")
        if cand.channel != channel:
            raise ModelSpecError(f"{source}: [{channel}] effect {text!r} belongs to channel {cand.channel}")
        return Term(cand.coefficient, cand.term, cand.name)
    name, _, expr = text.partition("=")
    name, expr = name.strip(), expr.strip()
    if not name.isidentifier():
        raise ModelSpecError(f"{source}: [{channel}] coefficient name {name!r} is not a plain identifier")
    try:
        parse(expr, frozenset(SIGNALS))
    except ExpressionError as exc:
        raise ModelSpecError(f"{source}: [{channel}] {name}: {exc}") from exc
    return Term(name, expr.strip())


def default_models(vehicle=None) -> dict[str, ChannelModel]:
    """The default models: the vehicle file's ``[models]`` table when it has one, else the
    class's: AIRCRAFT_TERMS for an aircraft, method.md §11 for the finned seed-rlv class."""
    table = getattr(vehicle, "default_terms", None) or (
        AIRCRAFT_TERMS if getattr(vehicle, "vehicle_class", "finned") == "aircraft" else DEFAULT_TERMS)
    where = f"{vehicle.source} [models]" if getattr(vehicle, "default_terms", None) else "<default>"
    return {ch: ChannelModel(ch, parse_terms(terms, ch, where)) for ch, terms in table.items()}


def parse_terms(terms: list, channel: str, source: str = "<memory>", mach_reference: float = 12.4
                ) -> tuple[Term, ...]:
    """A channel's term list: at most MAX_TERMS terms, each parsed, no coefficient twice."""
    if len(terms) > MAX_TERMS:
        raise ModelSpecError(f"{source}: [{channel}] {len(terms)} terms: at most {MAX_TERMS} per channel")
    parsed = tuple(parse_term(t, channel, source, mach_reference) for t in terms)
    names = [t.coefficient for t in parsed]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ModelSpecError(f"{source}: [{channel}] coefficient(s) {sorted(dup)} appear twice")
    return parsed


def load_models(path: str | Path, base: dict[str, ChannelModel] | None = None,
                mach_reference: float = 12.4) -> dict[str, ChannelModel]:
    """Read a TOML spec; channels it does not mention keep `base` (default: the defaults).
    A channel table replaces (``terms``) or changes (``add``, ``remove``) base's model
    (aerosid.modelling.model_specs, which also says what changed)."""
    from aerosid.modelling.model_specs import read_spec

    return read_spec(path, base, mach_reference).models


def models_to_toml(models: dict[str, ChannelModel]) -> str:
    lines = []
    for ch, m in models.items():
        # catalogue effects by name; a Mach term about another reference Mach than the
        # catalogue's 12.4, and every extra candidate, as its expression (read back the same)
        terms = ", ".join(f'"{t.effect}"' if t.effect in CATALOGUE and CATALOGUE[t.effect].term == t.expression
                          else f'"{t.coefficient} = {t.expression}"'
                          for t in m.terms)
        lines.append(f"[{ch}]\nterms = [{terms}]\n")
    return "\n".join(lines)


#: Half-window of the alpha-dot / beta-dot derivative on band-limited flight data, in periods
#: of the band edge (0.3 / band: the Savitzky-Golay window's own corner sits near the band
#: edge).  The central difference of the band-limited vane angle carried enough vane noise
#: into alpha_dot_hat to bias C_m_alpha -3 % and the damping -9 % on c172x.
BAND_DERIVATIVE_CYCLES = 0.3


def signals_from_flight_data(fd: pd.DataFrame, d_m: float, lateral_m: float | None = None,
                             rate_half_window_s: float = RATE_HALF_WINDOW_S) -> dict[str, np.ndarray]:
    """The named signals of a FlightData frame (SI, radians).  d_m: the pitch reference
    length of q_hat [m] (d, or an aircraft's chord); lateral_m: that of p_hat and r_hat
    (an aircraft's span; default d_m); rate_half_window_s: the derivative window of
    alpha_dot_hat and beta_dot_hat [s].  The frame must be sorted by flight and time."""
    b_m = d_m if lateral_m is None else lateral_m
    t = fd["t_s"].to_numpy(float)
    alpha, beta = fd["alpha_rad"].to_numpy(float), fd["beta_rad"].to_numpy(float)
    groups = ((fd["flight"].astype(str) + "/" + fd["segment"].astype(str)).to_numpy()
              if {"flight", "segment"} <= set(fd.columns) else None)
    V = fd["V_m_s"].to_numpy(float)
    p, q, r = (fd[c].to_numpy(float) for c in ("p_rad_s", "q_rad_s", "r_rad_s"))
    if "band_hz" in fd.columns and np.all(np.isfinite(fd["band_hz"].to_numpy(float))):
        # band-limited flight data (aerosid.identification.band): alpha and beta went through
        # the common low-pass already; the derivative window follows the band edge
        band = float(np.min(fd["band_hz"].to_numpy(float)))
        derivative = lambda y: smooth_derivative(t, y, groups, BAND_DERIVATIVE_CYCLES / band)  # noqa: E731
    else:
        derivative = lambda y: smooth_derivative(t, y, groups, rate_half_window_s)  # noqa: E731
    return {
        "alpha": alpha, "beta": beta,
        "alpha_r": fd["alpha_r_rad"].to_numpy(float), "phi_r": fd["phi_r_rad"].to_numpy(float),
        "mach": fd["mach"].to_numpy(float), "V": V, "qbar": fd["qbar_pa"].to_numpy(float),
        "delta_p": fd["delta_p_rad"].to_numpy(float), "delta_y": fd["delta_y_rad"].to_numpy(float),
        "delta_r": fd["delta_r_rad"].to_numpy(float), "p": p, "q": q, "r": r,
        "p_hat": p * b_m / (2 * V), "q_hat": q * d_m / (2 * V), "r_hat": r * b_m / (2 * V),
        # alpha-dot, beta-dot: Savitzky-Golay derivative per flight segment
        "alpha_dot_hat": derivative(alpha) * d_m / (2 * V),
        "beta_dot_hat": derivative(beta) * b_m / (2 * V),
        "t": t,
        # fin rates [rad/s] (a control lag tau shows as -tau x the fin term's coefficient on them)
        **{f"{c}_dot": smooth_derivative(t, fd[f"{c}_rad"].to_numpy(float), groups, FIN_RATE_HALF_WINDOW_S)
           for c in ("delta_p", "delta_y", "delta_r")},
    }


#: alpha_dot_hat of a vane aircraft from the flight-path kinematics above a corner and the
#: vanes below it (aerosid.modelling.flight_path).  Off: measured worse than the vane derivative
#: (docs/estimation.md, "alpha-dot from the flight-path kinematics"): exact alpha-dot is nearly
#: q + a_n/V, which makes C_m_alpha and C_m_alpha_dot confounded (VIF 84 -> 222 on pa28).
KINEMATIC_ALPHA_DOT = False
#: ... and alpha itself from the same complementary filter (needs KINEMATIC_ALPHA_DOT).  Off too.
KINEMATIC_ALPHA = False


def kinematic_angles(fd: pd.DataFrame, vehicle) -> bool:
    """vehicle_signals takes alpha_dot_hat (and, with KINEMATIC_ALPHA, alpha) of this flight data
    from the flight-path kinematics, which read the rates p, q, r: KINEMATIC_ALPHA_DOT set (off by
    default), a vane aircraft, and the kinematic columns present."""
    if not KINEMATIC_ALPHA_DOT:  # the default: nothing more to look at (called per SIMEX frame)
        return False
    from aerosid.modelling.flight_path import KINEMATIC_COLUMNS

    return (getattr(vehicle, "air_data_source", None) == "vanes" and len(fd) > 0
            and set(KINEMATIC_COLUMNS) <= set(fd.columns))


def vehicle_signals(fd: pd.DataFrame, vehicle, with_band_order: bool = True,
                    like: dict | None = None) -> dict[str, np.ndarray]:
    """signals_from_flight_data with the vehicle's pitch and lateral reference lengths.

    With ``with_band_order`` (the default) and band-path flight data, the signals also carry the flight
    data's band order and their rows (aerosid.identification.band_order): every term evaluated
    from them, by a model's design or a candidate, is then the band path's column of a non-linear
    term, LP(f(x)) rather than f(LP(x)).  like: the signals of the flight data fd is a copy of, row
    for row (a SIMEX frame: noise on the low-passed signals, the wide-band ones untouched): their
    band order is reused rather than looked up again (~1000 frames per identify).

    With vanes (``[air_data] source = "vanes"``) and KINEMATIC_ALPHA_DOT set, alpha_dot_hat comes
    from the flight-path kinematics (rates, the specific forces -C_A, -C_N times qbar S/m) above
    f_c = band / 5 and from the vane angle below (aerosid.modelling.flight_path); with
    KINEMATIC_ALPHA alpha too (alpha_r, phi_r recomputed).  Both are off by default: on 10 cached
    JSBSim flights each (identify, SIMEX on) C_m_alpha mean / RMS error went pa28 -4.0 / 5.7 ->
    -6.0 / 9.7 %, F4N -4.9 / 5.2 -> -13.1 / 16.7 %, OV10 +3.0 / 3.2 -> -2.3 / 2.6 %
    (bench/results/kinematic_adot.md).  SIMEX (aerosid.identification.eiv) calls this function
    on each perturbed frame; with the kinematics on, the channels its gyro part leaves out rebuild
    their signals from the measured rates (aerosid.identification.eiv_fit._with_measured_rates)."""
    sig = signals_from_flight_data(fd, vehicle.length_pitch_m, vehicle.length_lateral_m,
                                   vehicle.derivative_half_window_s)
    if kinematic_angles(fd, vehicle):
        from aerosid.modelling.flight_path import flight_data_alpha
        from aerosid.identification.inversion import total_angles

        band = fd["band_hz"].to_numpy(float) if "band_hz" in fd.columns else np.array([np.nan])
        # the band edge of band-limited flight data, else the Savitzky-Golay window's corner
        edge = (float(np.min(band)) if np.all(np.isfinite(band))
                else 1.0 / (2.0 * vehicle.derivative_half_window_s))
        groups = ((fd["flight"].astype(str) + "/" + fd["segment"].astype(str)).to_numpy()
                  if {"flight", "segment"} <= set(fd.columns) else None)
        kin = flight_data_alpha(fd, sig, vehicle, edge, groups)
        if KINEMATIC_ALPHA:
            sig["alpha"] = kin.alpha
            sig["alpha_r"], sig["phi_r"] = total_angles(kin.alpha, sig["beta"])
        sig["alpha_dot_hat"] = kin.alpha_dot * vehicle.length_pitch_m / (2 * sig["V"])
    if with_band_order and like is not None and len(like.get(ROW_KEY, ())) == len(fd):
        sig[BAND_ORDER_KEY], sig[ROW_KEY] = like.get(BAND_ORDER_KEY), like[ROW_KEY]
    elif with_band_order:
        from aerosid.identification.band_order import band_order

        sig[BAND_ORDER_KEY] = band_order(fd, vehicle)
        sig[ROW_KEY] = np.arange(len(fd))
    return sig
