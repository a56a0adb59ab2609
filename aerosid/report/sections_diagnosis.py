"""The diagnosis section: message, ranked effects, where the model fails, whiteness."""
from __future__ import annotations

from aerosid.report.html import _H, _align, _cell, _e, _finite, _heat, _num, _p, _pct, _q, _note, _span, _table, render
from aerosid.report.plots import DEG, _svg, regime_figure
from aerosid.report.rundir import Shown, _Run, diagnosed_model


def identity_channels(doc: dict | None, shown: Shown) -> tuple[str, ...]:
    """Channels that are identities by construction: diagnosis.json's ``identities`` when it
    records them, else the ones the shown coefficients table marks so."""
    ids = (doc or {}).get("identities")
    if isinstance(ids, (list, tuple)):
        return tuple(str(c) for c in ids)
    return shown.identities


def _recommended(doc: dict) -> dict | None:
    """The explicit recommendation (diagnosis.json ``recommended``), when the key is there."""
    if "recommended" not in doc:
        return None
    rec = doc.get("recommended")
    if isinstance(rec, dict):
        return {"name": rec.get("name"), "detail": {k: v for k, v in rec.items() if k != "name"}}
    return {"name": rec, "detail": {}}


def _floor_rows(floor) -> list:
    """Rows (channel, residual RMS, floor RMS, excess RMS, excess share, the floor's coefficient,
    and angle parts) of ``floor``."""
    if not isinstance(floor, dict):
        return []
    rows = []
    for ch, f in floor.items():
        if not isinstance(f, dict):
            continue
        res, flo, exc = f.get("residual_rms"), f.get("floor_rms"), f.get("excess_rms")
        share = float(exc) / float(res) if _finite(exc) and _finite(res) and float(res) > 0 else None
        rows.append((ch, _num(res, ".3g"), _num(flo, ".3g"), _num(exc, ".3g"), _pct(share, ".0f"),
                     _num(f.get("coefficient_floor_rms"), ".3g"), _num(f.get("angle_floor_rms"), ".3g")))
    return rows


# --------------------------------------------------------------------------- diagnosis
def _s_diagnosis(doc: dict | None, diag, source: str, run: _Run, shown: Shown) -> str:
    if doc is None:
        return _note("No diagnosis yet for this run. Run `aerosid diagnose RUN_DIR` (it writes diagnosis.json), "
                     "then regenerate the report.")
    which = diagnosed_model(doc, diag, shown)
    identities = identity_channels(doc, shown)
    window = doc.get("mach_window") or [None, None]
    out = [render("diagnosis_head.html.j2", source=source, model=which or "unknown (not recorded, and no stored "
                  "version has its terms)", n_samples=doc.get("n_samples", "?"), mach_lo=_num(window[0], ".2f"),
                  mach_hi=_num(window[-1], ".2f"), shown=shown.version,
                  stale=bool(shown.version and which != shown.version), message=doc.get("message", "(no message)"),
                  rule=(doc.get("rule") or {}).get("text"), identities=identities,
                  recommended=_recommended(doc), floor=_floor_rows(doc.get("floor")))]
    for key, title in (("lookalikes", "Look-alike candidates compared"),
                       ("localisation", "Localisation: where the residual points")):
        if doc.get(key):
            out.append(render("generic.html.j2", id=key, title=title, value=doc[key]))
    out.append("<h3 id=\"effects\">Candidate effects, ranked</h3>")
    effects = doc.get("effects") or []
    if not effects:
        out.append(_note("No candidate effects were tested."))
    else:
        out.append(_p("Each candidate physical effect was added in turn to its channel's model. F and p are "
                      "corrected for coloured residuals (plain F shown for comparison, typically far larger); "
                      "variance share is the part of the residual variance it explains; consistency is the "
                      "leave-one-window-out check; EIV fraction near 1 means an artefact of angle errors."))
        rows = []
        for i, e in enumerate(effects, 1):
            why = (e.get("meaning") if e.get("significant") else
                   "; ".join(e.get("reasons") or []) or e.get("meaning")) or ""
            if e.get("confused_with"):
                why += f" [confusable with {', '.join(e['confused_with'])}]"
            cells = [i, e.get("name"), e.get("channel"), _H('<b class="yes">YES</b>') if e.get("significant")
                     else "no", _num(e.get("estimate"), ".3g"), _num(e.get("partial_f_corrected"), ".3g"),
                     _num(e.get("p_value"), ".2g"), _num(e.get("partial_f_plain"), ".3g"),
                     _pct(e.get("variance_share"), ".2f"), _num(e.get("pse_drop"), ".3f"),
                     _pct(e.get("window_consistency"), ".0f"), _pct(e.get("rms_drop_fraction"), ".1f"),
                     _num(e.get("eiv_fraction"), ".2f"), _num(e.get("p_value_simex"), ".2g")]
            attr = ' class="significant"' if e.get("significant") else ""
            rows.append(_H(f"<tr{attr}>" + "".join(f"<td{_align(c)}>{_cell(c)}</td>" for c in cells) + "</tr>"))
            label = "meaning" if e.get("significant") else "why not"
            rows.append(_H(f'<tr class="why"><td></td><td colspan="{len(cells) - 1}">{_e(label)}: {_e(why)}</td>'
                           "</tr>"))
        out.append(_table(["#", "effect", "channel", "significant", "estimate", "F corrected", "p", "F plain",
                           "variance share", "PSE drop", "consistency", "RMS drop", "EIV fraction", "p SIMEX"],
                          rows, id="effects-table", cls="effects"))
    out.append("<h3 id=\"where\">Where the model fails</h3>")
    if identities:
        out.append(_p(f"Left out: {', '.join(identities)}, identities by construction (their residual is "
                      "numerical, ~1e-6, because alpha and beta are inverted from them)."))
    out.append(_windows([w for w in doc.get("time_windows") or [] if w.get("channel") not in identities]))
    out.append(_regimes(doc, diag, identities))
    out.append("<h3 id=\"whiteness\">Whiteness of the residuals</h3>")
    out.append(_whiteness(doc.get("whiteness") or {}))
    return "\n".join(out)


def _windows(wins: list) -> str:
    if not wins:
        return _note("No time-window statistics in the diagnosis.")
    by_ch: dict = {}
    for w in wins:
        by_ch.setdefault(w.get("channel"), []).append(w)
    ref = next(iter(by_ch.values()))
    heads = ["channel"] + [_H(f"{int(w.get('index', j)) + 1}<br><small>{_e(_span(w.get('t_start_s'), w.get('t_end_s')))}"
                              "</small>") for j, w in enumerate(ref)]
    rows = []
    for ch, ws in by_ch.items():
        cells = [f"<th>{_e(ch)}</th>"]
        for w in ws:
            mark = " ◆" if w.get("worst") else ""
            title = (f"t {_span(w.get('t_start_s'), w.get('t_end_s'))}, RMS {_num(w.get('rms'), '.3g')}, mean "
                     f"{_num(w.get('mean'), '.3g')}, n {w.get('n')}")
            cls = ' class="flagged"' if w.get("flagged") else ""
            cells.append(f'<td{cls} style="background:{_heat(w.get("rms_ratio"))}" title={_q(title)}>'
                         f'×{_e(_num(w.get("rms_ratio"), ".2f"))}{mark}</td>')
        rows.append(_H("<tr>" + "".join(cells) + "</tr>"))
    return (_p("Residual RMS per time window relative to the channel's whole-flight RMS (×1 = average; red = "
               "worse, flagged in bold at ≥ 1.5×; ◆ = the channel's worst window). Hover a cell for the numbers.")
            + _table(heads, rows, id="windows-heat", cls="heat"))


def _regime_bins(doc: dict, diag) -> tuple[list[dict], bool]:
    """(bins as dicts, whether they are the full map): the Diagnosis object's every bin,
    else diagnosis.json's ``regime_map`` (every bin), else its ``regimes`` (the worst 3)."""
    if diag is not None and getattr(diag, "channels", None):
        return [b.to_dict() for rep in diag.channels.values() for b in rep.regimes], True
    if doc.get("regime_map"):
        return list(doc["regime_map"]), True
    return list(doc.get("regimes") or []), False


def _in_unit(x, unit: str) -> tuple[str, str]:
    if unit == "rad":
        return _num(float(x) * DEG if _finite(x) else None, ".3g"), "deg"
    if unit == "Pa":
        return _num(float(x) * 1e-3 if _finite(x) else None, ".3g"), "kPa"
    return _num(x, ".4g"), unit


def _regimes(doc: dict, diag, identities=()) -> str:
    bins, full = _regime_bins(doc, diag)
    bins = [b for b in bins if b.get("channel") not in identities and _finite(b.get("lo")) and _finite(b.get("hi"))]
    if not bins:
        return _note("No regime statistics in the diagnosis.")
    flag = (doc.get("rule") or {}).get("flag_ratio", 1.5)
    rows = []
    worst = sorted((b for b in bins if b.get("flagged")), key=lambda b: -(b.get("rms_ratio") or 0)) if full else bins
    for r in worst:
        lo, unit = _in_unit(r.get("lo"), r.get("unit", ""))
        hi, _ = _in_unit(r.get("hi"), r.get("unit", ""))
        rows.append((r.get("channel"), r.get("variable"), f"{lo} .. {hi} {unit}", r.get("n"), _num(r.get("rms"), ".3g"),
                     _H(f'<span style="background:{_heat(r.get("rms_ratio"))}">×{_e(_num(r.get("rms_ratio"), ".2f"))}'
                        "</span>"), bool(r.get("flagged"))))
    head = ["channel", "variable", "bin", "samples", "RMS", "ratio", "flagged"]
    if not full:
        return (_p("The worst regime bins per channel (this diagnosis.json keeps only the 3 worst of each; a newer "
                   "`aerosid diagnose` stores the whole map): residual RMS in the bin relative to the channel's. "
                   "Angles in degrees.")
                + _table(head, rows, id="regimes-worst"))
    by_var: dict = {}
    for b in bins:
        unit_map = by_var.setdefault(b.get("variable"), (b.get("unit", ""), {}))[1]
        unit_map.setdefault(b.get("channel"), []).append(b)
    out = [_p(f"Residual map by regime: the samples are cut into quantile bins of each variable; each step is the "
              f"residual RMS in that bin relative to the channel's whole-flight RMS (×1 = average; dashed red line: "
              f"flagged at ≥ {_num(flag, 'g')}× with enough samples). Angles in degrees. On a flight where Mach "
              "falls steadily, a Mach bin is also a time span."),
           _svg(regime_figure(by_var, float(flag) if _finite(flag) else 1.5), "regimes",
                "Residual RMS ratio by regime bin, per variable and channel")]
    out.append(_table(head, rows, id="regimes-flagged", caption="Flagged regime bins, worst first") if rows else
               _p("No regime bin is flagged."))
    return "\n".join(out)


def _whiteness(wh: dict) -> str:
    if not wh:
        return _note("No whiteness statistics in the diagnosis.")
    lags = list(dict.fromkeys(k for w in wh.values() for k in (w.get("acf") or {})))
    rows = []
    for ch, w in wh.items():
        bands = w.get("spectrum_band_share") or w.get("band_share") or {}
        band_txt = "; ".join(f"{k}: {100 * v:.0f}\u00a0%" for k, v in bands.items() if _finite(v))
        rows.append([ch, f"{_num(w.get('ljung_box_stat'), '.4g')} (lag {w.get('ljung_box_lag', '?')})",
                     _num(w.get("ljung_box_p"), ".2g"), bool(w.get("white")),
                     *(_num((w.get("acf") or {}).get(k), ".2f") for k in lags),
                     _num(w.get("correlation_time_s"), ".2f"), f"{_num(w.get('n_eff'), '.0f')} / {w.get('n', '?')}",
                     w.get("dominant_band", ""), band_txt])
    return (_p("Ljung–Box tests whether the residual is white; smoothed flight data always give coloured residuals "
               "(p ≈ 0 is expected), which is why the significance tests above use coloured-residual statistics. "
               "What matters is where the residual power sits (dominant band) and how long it stays correlated.")
            + _table(["channel", "Ljung–Box Q", "p", "white", *(f"ACF {k}" for k in lags), "correlation time [s]",
                      "N_eff / N", "dominant band", "power share by band"], rows, id="whiteness-table"))


