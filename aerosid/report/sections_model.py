"""Report sections about the model: the coefficients table and measured vs model."""
from __future__ import annotations

import math

import numpy as np

from aerosid.report.html import CHANNELS, _H, _e, _finite, _num, _p, _q, _note, _table
from aerosid.report.plots import DEG, _figure, _gaps, _svg, _thin, scatter_panel
from aerosid.report.rundir import Shown, _Run, diagnosed_model

IDENTITY_TEXT = ("alpha and beta are inverted from this channel through the preflight force database, so its fit "
                 "returns that database: not identifiable from this telemetry")


def _s_coefficients(run: _Run, shown: Shown, truth: dict) -> str:
    from aerosid.identification.identify import ANGLE_TERMS
    from aerosid.identification.term_report import UNDETERMINED_NOTE, WRONG_SIGN_NOTE, undetermined, wrong_sign

    table = shown.table
    if table is None or table.empty:
        return _note(run.unreadable(shown.table_name) or
                     f"No {shown.table_name}: the regression has not run (or every segment failed).")
    identities = shown.identities
    has_truth = bool(truth)
    headers = ["coefficient", "per", "preflight", "estimate", "σ corrected", "σ OLS", "95 % interval"]
    if has_truth:
        headers += ["truth", "error %", "truth in interval"]
    ncol = len(headers)
    rows = []
    weak_terms = set(undetermined(table))
    signed_terms = set(wrong_sign(table))
    for channel, g in table.groupby("channel", sort=False):
        first = g.iloc[0]
        head = (f"{channel}: F = {_num(first.get('f_stat'), ',.0f')} (corrected "
                f"{_num(first.get('f_stat_corrected'), ',.1f')}), R² = {_num(first.get('r2'), '.4f')}, PSE = "
                f"{_num(first.get('pse'), '.3g')}, condition number {_num(first.get('condition_number'), '.1f')}, "
                f"N = {first.get('n_obs', '?')} (effective {_num(first.get('n_eff'), '.0f')}), residual RMS "
                f"{_num(first.get('rms_residual'), '.3g')}")
        if channel in identities:
            head = f"{channel}: identity by construction ({IDENTITY_TEXT})"
        rows.append(_H(f'<tr class="channel"><th colspan="{ncol}" id={_q("coef-" + str(channel))}>{_e(head)}'
                       "</th></tr>"))
        for _, r in g.iterrows():
            expr = str(r.get("expression", "") or "").replace(" ", "")
            angle = expr in ANGLE_TERMS
            k = math.pi / 180 if angle else 1.0
            per = ("deg pair" if expr in ("delta_p/2", "delta_y/2") else "deg") if angle else "—"
            est = r.get("estimate")
            ident = bool(r.get("identifiable", True)) and _finite(est)
            ref = r.get("reference")
            # a q_hat term also takes up Cm_alpha_dot (alpha-dot ~ q in a short-period manoeuvre): when the
            # truth gives the sum (a JSBSim flight), that is what the estimate is compared with
            name = str(r["coefficient"])
            merged = name == "Cm_q" and "Cm_alpha_dot" not in set(g["coefficient"])
            tv = (truth.get("Cm_q_plus_alpha_dot", truth.get(name)) if merged else truth.get(name)) if has_truth else None
            if not ident:
                why = ("identity by construction" if channel in identities else
                       f"not identifiable (no excitation in {expr or 'its term'})")
                cells = [str(r["coefficient"]), per, _sc(ref, k), _H(f'<span class="na">{_e(why)}</span>'),
                         "", "", ""]
                if has_truth:
                    cells += [_sc(tv, k), "—", "—"]
                rows.append(cells)
                continue
            lo, hi = r.get("ci_low"), r.get("ci_high")
            cells = [str(r["coefficient"]), per, _sc(ref, k), _sc(est, k), _sc(r.get("std_error"), k, ".2g"),
                     _sc(r.get("std_error_ols"), k, ".2g"), f"[{_num(_k(lo, k), '.5g')}, {_num(_k(hi, k), '.5g')}]"]
            if name in weak_terms:
                cells[-1] = _H(f'{_e(cells[-1])}<br><span class="na">{_e(UNDETERMINED_NOTE)}</span>')
            elif name in signed_terms:
                cells[-1] = _H(f'{_e(cells[-1])}<br><span class="na">{_e(WRONG_SIGN_NOTE)}</span>')
            if has_truth:
                if tv is None:
                    cells += ["—", "—", "—"]
                else:
                    err = (f"{100 * (float(est) - tv) / abs(tv):+.3g}" if tv != 0 else
                           f"abs {float(est) * k - tv * k:+.3g}")
                    within = _finite(lo) and _finite(hi) and float(lo) <= tv <= float(hi)
                    cells += [_sc(tv, k), err, within]
            rows.append(cells)
        for i, w in enumerate(w for w in str(first.get("warnings", "") or "").split(" | ") if w):
            rows.append(_H(f'<tr class="warning"><td colspan="{ncol}">warning [{i + 1}] {_e(w)}</td></tr>'))
    intro = _p(f"Model shown: {shown.label}. Moments about the CG. Angle slopes are printed per degree (pitch and yaw fin slopes per degree "
               "pair, i.e. per degree of δ/2), every other coefficient per unit of its term; coefficients.parquet "
               "holds them in SI per radian. σ corrected accounts for the coloured residuals (Morelli–Klein); σ "
               "OLS is the plain least-squares value, shown for comparison; the 95 % interval uses the corrected "
               "σ. Preflight is the database value the flight is compared with."
               + (" Truth is the simulator's true value (truth.json); error % is relative to it." if has_truth
                  else "")
               + (" Without a Cm_alpha_dot term, Cm_q is compared with Cm_q + Cm_α̇ (truth.json's "
                  "Cm_q_plus_alpha_dot): the q d/(2V) term then takes up both." if has_truth
                  and "Cm_q_plus_alpha_dot" in truth else ""))
    return intro + _table(headers, rows, id="coefficients", cls="coefficients")


def _k(x, k):
    return float(x) * k if _finite(x) else None


def _sc(x, k, fmt=".5g") -> str:
    return _num(_k(x, k), fmt)




# --------------------------------------------------------------------------- the shown model on the flight data
def model_series(run: _Run, shown: Shown) -> dict:
    """The shown model evaluated on the flight data (the samples inside its Mach window):
    {"source": text, "t", "mach", "qbar", "channels": {ch: {measured, model, residual, rms,
    r2, terms: [(coefficient, expression, estimate, x)]}}}; {} when there is nothing to compare."""
    fd = run.frame("flight_data.parquet")
    table = shown.table
    if fd is None or table is None or table.empty or fd.empty:
        return {}
    from aerosid.modelling.expressions import evaluate
    from aerosid.identification.identify import mach_window_mask
    from aerosid.modelling.models import signals_from_flight_data
    from aerosid.vehicles.vehicle import load_vehicle

    veh = load_vehicle(run.vehicle)
    fd = fd.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    fd = fd.loc[mach_window_mask(fd["mach"].to_numpy(float), veh.mach_reference, shown.mach_half_width)]
    fd = fd.reset_index(drop=True)
    if fd.empty:
        return {}
    sig = signals_from_flight_data(fd, veh.length_pitch_m, veh.length_lateral_m)
    n = len(fd)
    chans = {}
    for ch, g in table.groupby("channel", sort=False):
        if ch not in fd:
            continue
        model = np.zeros(n)
        terms = []
        for _, r in g.iterrows():
            if _finite(r.get("estimate")) and r.get("expression"):
                x = np.asarray(evaluate(str(r["expression"]), sig, n), float) * np.ones(n)
                model += float(r["estimate"]) * x
                terms.append((str(r["coefficient"]), str(r["expression"]), float(r["estimate"]), x))
        y = fd[ch].to_numpy(float)
        chans[str(ch)] = {"measured": y, "model": model, "residual": y - model, "terms": terms,
                          "rms": float(g.iloc[0].get("rms_residual", np.nan)), "r2": float(g.iloc[0].get("r2", np.nan))}
    source = (f"{shown.label}: its coefficients ({shown.table_name}) on the flight data inside its Mach window"
              if shown.version else "the coefficients of coefficients.parquet (Mach window of the fit)")
    return {"source": source, "t": fd["t_s"].to_numpy(float), "mach": fd["mach"].to_numpy(float),
            "qbar": np.asarray(sig["qbar"], float) * np.ones(n), "channels": chans}


def _order(chans) -> list[str]:
    return [c for c in CHANNELS if c in chans] + [c for c in chans if c not in CHANNELS]


def _flagged_windows(doc: dict | None, diag, shown: Shown) -> tuple[dict, str]:
    """channel -> flagged (t0, t1) windows of the diagnosis when it is of the shown version."""
    if not doc:
        return {}, ""
    which = diagnosed_model(doc, diag, shown)
    if shown.version is None or which != shown.version:
        return {}, (f" The diagnosis is of {which or 'another model'}, not of {shown.version}: its flagged windows "
                    "are not shaded." if shown.version else "")
    out: dict = {}
    for w in doc.get("time_windows") or []:
        if w.get("flagged") and _finite(w.get("t_start_s")) and _finite(w.get("t_end_s")):
            out.setdefault(w.get("channel"), []).append((float(w["t_start_s"]), float(w["t_end_s"])))
    return out, f" The time windows the diagnosis of {which} flags are shaded."


def _s_comparison(run: _Run, shown: Shown, series: dict, doc: dict | None, diag) -> str:
    if not series:
        bad = [e for e in (run.unreadable("flight_data.parquet"), run.unreadable(shown.table_name)) if e]
        return _note("; ".join(bad) if bad else
                     "No flight data or no coefficients in this run folder: nothing to compare.")
    flagged, shade = _flagged_windows(doc, diag, shown)
    identities = shown.identities
    out = [_p(f"Each channel's flight-derived (measured) coefficient against the model output, over time, with the "
              f"residual (measured − model) below. Model: {series['source']}.{shade} A good model leaves a residual "
              "without structure; steps, drifts or oscillations in it point at a missing effect.")]
    label = shown.version or "coefficients.parquet"
    for i, ch in enumerate(_order(series["channels"])):
        c = series["channels"][ch]
        out.append(f'<h3 id={_q("cmp-" + ch)}>{_e(ch)}</h3>')
        if ch in identities:
            out.append(_note(f"{ch} is an identity by construction ({IDENTITY_TEXT}): its model reproduces the "
                             "measurement to rounding (least-squares residual RMS " + _num(c["rms"], ".2g") +
                             ") and says nothing about the model. Not plotted; left out of the residual plots and of "
                             "where the model fails."))
            continue
        plotted = float(np.sqrt(np.mean(np.square(c["residual"])))) if c["residual"].size else float("nan")
        out.append(_p(f"Residual RMS of the plotted model {_num(plotted, '.3g')} (of the plain least-squares fit "
                      f"{_num(c['rms'], '.3g')}; the two differ when the estimates were corrected for the noise in "
                      f"the angles), R² {_num(c['r2'], '.5f')}, {len(series['t'])} samples."))
        fig, (a1, a2) = _figure((9, 4.2), 2, [2, 1])
        th = _thin(len(series["t"]))
        t, y, m, res = _gaps(series["t"][th], c["measured"][th], c["model"][th], c["residual"][th])
        a1.plot(t, y, "-", color="tab:blue", lw=0.7, label="measured (flight-derived)")
        a1.plot(t, m, "-", color="tab:orange", lw=1.0, label=f"model {label}")
        a1.set_ylabel(ch)
        a1.legend(loc="best", fontsize=8)
        a2.plot(t, res, "-", color="tab:green", lw=0.6)
        a2.axhline(0, color="0.3", lw=0.6)
        for a, b in flagged.get(ch, ()):
            a2.axvspan(a, b, color="tab:red", alpha=0.15)
        a2.set_ylabel("residual")
        a2.set_xlabel("t [s]")
        out.append(_svg(fig, f"cmp{i}", f"{ch}: measured vs model {label} (top) and residual (bottom) against time"))
    return "\n".join(out)


def _axis(expression: str) -> tuple[float, str]:
    from aerosid.identification.identify import ANGLE_TERMS

    e = expression.replace(" ", "")
    return (DEG, f"{e} [deg]") if e in ANGLE_TERMS else (1.0, e)


def _s_residuals(run: _Run, shown: Shown, series: dict) -> str:
    if not series:
        return _note("No flight data or no coefficients in this run folder: no residuals to plot.")
    identities = shown.identities
    label = shown.version or "coefficients.parquet"
    out = [_p(f"Model: {series['source']}. Top row, per term: the partial residual (residual + the term's fitted "
              "contribution) against the term's regressor, with the fitted contribution as a red line: points "
              "that bend away from the line show the term's true shape (a cubic, a saturation, a step). Middle "
              "row: the residual against the same regressor; bottom row: against Mach, dynamic pressure and time. "
              "Grey dots are a sample of the points; the blue line and band are the mean and the 10–90 % range per "
              "bin of the regressor. Angles in degrees."
              + (f" Left out (identities by construction): {', '.join(identities)}." if identities else ""))]
    extra = [("Mach [-]", series["mach"]), ("q̄ [kPa]", series["qbar"] * 1e-3), ("t [s]", series["t"])]
    for i, ch in enumerate(_order(series["channels"])):
        if ch in identities:
            continue
        c = series["channels"][ch]
        terms = [tm for tm in c["terms"] if np.ptp(tm[3]) > 0]
        ncols = max(len(terms), len(extra), 1)
        nrows = 3 if terms else 1  # a model of constants only: the residual against Mach, qbar, t alone
        fig, axes = _figure((2.4 * ncols, 2.2 * nrows), nrows=nrows, ncols=ncols)
        axes = axes.reshape(nrows, ncols)
        for j, (name, expr, est, x) in enumerate(terms):
            k, xlabel = _axis(expr)
            grid = np.linspace(float(np.min(x)), float(np.max(x)), 2)
            scatter_panel(axes[0, j], x * k, c["residual"] + est * x, xlabel=xlabel, ylabel=f"{ch} partial: {name}",
                          line=(grid * k, est * grid))
            scatter_panel(axes[1, j], x * k, c["residual"], xlabel=xlabel, ylabel=f"{ch} residual")
        for j, (xlabel, x) in enumerate(extra):
            scatter_panel(axes[nrows - 1, j], x, c["residual"], xlabel=xlabel, ylabel=f"{ch} residual")
        for row, used in enumerate((len(terms), len(terms), len(extra)) if terms else (len(extra),)):
            for ax in axes[row, used:]:
                ax.set_visible(False)
        out.append(f'<h3 id={_q("res-" + ch)}>{_e(ch)}</h3>')
        out.append(_svg(fig, f"res{i}", f"{ch}, model {label}: " + (
            "partial residuals (top), residual against each regressor (middle) and against Mach, dynamic "
            "pressure and time (bottom)" if terms else "residual against Mach, dynamic pressure and time")))
    return "\n".join(out)
