"""``validation.html``: one self-contained page of an ``aerosid validate`` result.

The TIC/RMS tables, measured vs predicted time histories with their residuals
(per simulated output and per coefficient channel), the re-estimated intercepts
and the model used.  Same conventions as ``report.html`` (aerosid.report): inline
SVG with text drawn as paths, no script, stylesheet, font or image to fetch.
"""
from __future__ import annotations

import math
from datetime import datetime, timezone

from aerosid.report import _CSS, _e, _figure, _gaps, _note, _p, _svg, _table, _thin

#: plotted in these units (the data stay SI/radians)
_PLOT_SCALE = {"rad": (180 / math.pi, "deg"), "rad/s": (180 / math.pi, "deg/s"), "m/s^2": (1.0, "m/s^2"),
               "-": (1.0, "-")}


def _metric_rows(metrics) -> list:
    rows = []
    for m in metrics:
        k, unit = _PLOT_SCALE.get(m.unit, (1.0, m.unit))
        rms = f"{m.rms:.4g} {m.unit}" + (f" ({m.rms * k:.3g} {unit})" if unit != m.unit else "")
        rows.append([m.name, m.n, m.tic, rms, m.nrms, m.offset if math.isfinite(m.offset) else "—", m.source])
    return rows


def _history_plot(frame, names: list[str], units: dict, key: str, label: str, metrics=()) -> str:
    t = frame["t_s"].to_numpy(float)
    th = _thin(len(t))
    fig, axes = _figure((9, 1.9 * 2 * len(names)), nrows=2 * len(names), height_ratios=[2, 1] * len(names))
    for i, name in enumerate(names):
        k, unit = _PLOT_SCALE.get(units[name], (1.0, units[name]))
        y = frame[f"measured_{name}"].to_numpy(float) * k
        yh = frame[f"predicted_{name}"].to_numpy(float) * k
        top, bottom = axes[2 * i], axes[2 * i + 1]
        tt, yy, yyh = _gaps(t[th], y[th], yh[th])
        top.plot(tt, yy, "-", color="0.35", lw=0.8, label="measured")
        top.plot(tt, yyh, "-", color="tab:red", lw=1.0, label="predicted")
        top.set_ylabel(f"{name.split('_')[0]} [{unit}]")
        top.legend(loc="upper right", fontsize=8)
        m = next((m for m in metrics if m.name == name), None)
        if m is not None and math.isfinite(m.tic):
            top.set_title(f"{name}: TIC {m.tic:.3f}, RMS / std {m.nrms:.2f}", loc="left", fontsize=9)
        tt, rr = _gaps(t[th], (y - yh)[th])
        bottom.plot(tt, rr, "-", color="tab:blue", lw=0.8)
        bottom.axhline(0.0, color="0.5", lw=0.6)
        bottom.set_ylabel("residual")
    axes[-1].set_xlabel("t [s]")
    return _svg(fig, key, label)


def build_validation_report(result) -> str:
    """The HTML document of a ValidationResult (str)."""
    generated = datetime.now(timezone.utc).isoformat(timespec="seconds")
    title = f"aerosid validation — {result.telemetry}"
    head = ["output", "N", "TIC", "RMS error", "RMS / std", "offset removed", "measured by"]
    parts = [
        "<section id=\"summary\"><h2>What was predicted</h2>",
        _p(f"Run {result.run_dir}, model {result.model.source}, vehicle {result.vehicle}. Other manoeuvre: "
           f"{result.telemetry}: {result.n_predicted} of {result.n_samples} samples predicted, Mach "
           f"{result.mach_window[0]:.3g}..{result.mach_window[1]:.3g} (the identification's Mach window)."),
        _p(f"Bias treatment: {result.bias}. " + {
            "none": "The model as identified, nothing adjusted.",
            "offsets": "A constant per output and span (the mean of measured minus predicted) is added to the "
                       "prediction, as SIDPAC's Twin Otter prediction does.",
            "intercepts": "The simulated channels' intercepts are re-estimated on this manoeuvre by output "
                          "error, and output offsets removed; every other coefficient is as identified."}[result.bias]),
        _table(["quantity", "source"], [[k, v] for k, v in result.sources.items()]),
        *(_note(n) for n in result.notes),
        "</section>",
        "<section id=\"outputs\"><h2>Output prediction</h2>",
        _p("The identified model simulated with the other manoeuvre's measured controls, airspeed, dynamic "
           "pressure and attitude, from its measured initial state. Theil's inequality coefficient (TIC): 0 is "
           "a perfect prediction; TIC of about 0.25–0.3 or less is read as a good predictor. TIC of a signal with "
           "a large mean (a_z) is small whatever the dynamics: RMS / std compares the error with the signal's "
           "own variation."),
    ]
    if result.outputs:
        parts.append(_table(head, _metric_rows(result.outputs), id="output-metrics"))
        for pr in result.predictions:
            names = list(pr.outputs)
            units = {o: next(m.unit for m in result.outputs if m.name == o) for o in names}
            parts.append(_history_plot(pr.frame[pr.frame["span"] >= 0], names, units, f"ax-{pr.axis}",
                                       f"{pr.axis} axis: measured (grey) and predicted (red) outputs, residual "
                                       "below (angles and rates in degrees)", result.outputs))
    else:
        parts.append(_note("No output prediction (see the notes above)."))
    if result.intercepts:
        parts.append(_table(["coefficient", "identified", "re-estimated on this manoeuvre"],
                            [[k, a, b] for k, (a, b) in result.intercepts.items()], id="intercepts"))
    parts += ["</section>", "<section id=\"coefficients\"><h2>Coefficient prediction</h2>",
              _p("The other manoeuvre's flight data (the same estimation as the run) and each channel's "
                 "coefficient predicted from its regressors with the identified values."),
              _table(["channel", *head[1:]], _metric_rows(result.coefficients), id="coefficient-metrics")]
    cf = result.coefficient_frame
    chans = [m.name for m in result.coefficients]
    if chans:
        parts.append(_history_plot(cf[cf["span"] >= 0], chans, {c: "-" for c in chans}, "coef",
                                   "Flight-derived (grey) and predicted (red) coefficients, residual below",
                                   result.coefficients))
    model_rows = [[r.channel, r.coefficient, r.expression, r.estimate] for r in result.model.table().itertuples()]
    parts += ["</section>", "<section id=\"model\"><h2>The model</h2>",
              _table(["channel", "coefficient", "term", "value (SI per rad)"], model_rows, id="model-table"),
              "</section>"]
    return "\n".join([
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">', f"<title>{_e(title)}</title>",
        f"<style>{_CSS}</style>", "</head>", "<body>", f"<header><h1>{_e(title)}</h1>",
        _p(f"Prediction of another manoeuvre with an identified model. Generated {generated}. SI units and "
           "radians unless a column or axis says otherwise."), "</header>",
        *parts,
        "<footer>" + _e("Self-contained: no scripts, no external files; plots are inline SVG. Produced by "
                        "aerosid.identification.validation_report.") + "</footer>",
        "</body>", "</html>", ""])
