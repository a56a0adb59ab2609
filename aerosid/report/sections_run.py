"""Report sections about the processing: the run facts, preprocessing, and the
filter/smoother per segment."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.report.html import _H, _align, _cell, _e, _finite, _num, _p, _q, _note, _span, _table
from aerosid.report.plots import _figure, _gaps, _svg, _thin
from aerosid.report.rundir import _Run, _flights, _jmeta, _meta

MEAS_UNITS = {"ax": "m/s^2", "ay": "m/s^2", "az": "m/s^2", "p": "rad/s", "q": "rad/s", "r": "rad/s"}
FLAG_MEANINGS = {
    "MISSING_ROW": "no raw row at this grid time (dropout or sync gap)",
    "NAN": "raw value NaN or infinite",
    "SENTINEL": "raw value is a sentinel (e.g. -9999)",
    "FROZEN": "value repeated exactly, far beyond the sensor's update interval (stuck sensor)",
    "OUTLIER": "isolated spike (robust two-sided test)",
    "OUT_OF_RANGE": "outside the physical bounds",
    "TIME_JITTER": "timestamp far from its grid point",
    "HELD": "repeats its sensor's last update (sample-and-hold); not a fault",
    "INTERPOLATED": "action: linearly interpolated across a short gap (or between a held sensor's updates)",
    "LONG_GAP": "action: left empty, gap longer than the interpolation limit",
    "EDGE_GAP": "action: left empty, gap at the start or end of the record",
}


def _s_header(run: _Run, generated: str) -> str:
    pre = run.last("preprocess")
    telemetry = run.run.get("telemetry") or ((pre or {}).get("inputs") or [{}])[0].get("path")
    sha = ((pre or {}).get("inputs") or [{}])[0].get("sha256")
    if sha is None and telemetry and Path(telemetry).is_file():
        from aerosid.provenance import sha256_file

        sha = sha256_file(telemetry) + " (hashed now: no ledger record)"
    reg = run.last("regression")
    code_run = (reg or pre or {}).get("code_version") or _meta(run.dir / "coefficients.parquet").get(
        "aerosid.code_version")
    processed = (reg or pre or {}).get("time_utc")
    try:
        from aerosid.provenance import code_version

        code_now = code_version()
    except Exception as exc:  # a broken install must not stop the report
        code_now = f"unknown ({type(exc).__name__})"
    status = run.run.get("status")
    subs = _flights(run)
    if subs:  # pooled manoeuvres: one line per telemetry file
        telemetry = "; ".join(f"{s.flight}: {s.run.get('telemetry')}" for s in subs)
        sha = "; ".join(f"{s.flight}: {((s.last('preprocess') or {}).get('inputs') or [{}])[0].get('sha256')}"
                        for s in subs)
    rows = [("flight", run.flight), ("vehicle", run.vehicle),
            ("telemetry files" if subs else "telemetry file", telemetry or "unknown"),
            ("telemetry SHA-256", sha or "unknown (no ledger record)"),
            ("air data", _air_data_text(run)),
            ("run status", status or "unknown (no run.json)"),
            ("run folder", str(run.dir)),
            ("processed (UTC)", processed or "unknown"),
            ("code version of the run", code_run or "unknown"),
            ("report generated (UTC)", generated), ("report code version", code_now)]
    if run.ledger and run.ledger[-1].get("run_id"):
        rows.insert(5, ("last run id", run.ledger[-1]["run_id"]))
    body = _table(["", ""], rows, id="run-facts", cls="facts")
    # pooled manoeuvres: each one's findings (its segments named with the flight), then the pool's
    body += _findings_table([*({**f, "segment": f"{s.flight} {f.get('segment', '')}".strip()}
                               for s in subs or () for f in (s.run.get("findings") or []) if isinstance(f, dict)),
                             *(run.run.get("findings") or [])])
    if run.errors:
        body += "".join(_note(e) for e in run.errors)
    return body


def _findings_table(findings: list) -> str:
    """The run's findings (aerosid.estimation.findings; run.json ``findings``), one row each with
    its time span: why the status is "ok with findings" and what was cut ('' when there are none)."""
    rows = [(str(f.get("kind", "")), str(f.get("segment", "")), str(f.get("channel", "")),
             _span(f.get("t0_s"), f.get("t1_s")), f.get("n_samples", "—"),
             "cut from the regression" if f.get("cut") else "reported", str(f.get("detail", "")))
            for f in findings if isinstance(f, dict)]
    if not rows:
        return ""
    return (_p(f"{len(rows)} finding(s): what went wrong where. The spans marked 'cut' were left out of the "
               "regression (with a margin); the rest of each segment was used.")
            + _table(["finding", "segment", "channel", "time span", "samples", "action", "detail"], rows,
                     id="run-findings", caption="Findings"))


def _air_data_text(run: _Run) -> str:
    """Where density, temperature, Mach and dynamic pressure came from, per flight
    (run.json ``air_data``, else flight_data.parquet's aerosid.air_data metadata)."""
    src = run.run.get("air_data")
    if not src:
        path = run.dir / "flight_data.parquet"
        src = _jmeta(_meta(path), "aerosid.air_data", {}) if path.is_file() else {}
    if not isinstance(src, dict) or not src:
        return "unknown (no record)"
    names = {"rho_kg_m3": "density", "T_static_K": "static temperature", "mach": "Mach", "qbar_pa": "dynamic pressure"}
    groups: dict[str, list[str]] = {}  # flights with the same sources share a line
    for fid, q in src.items():
        text = "; ".join(f"{names.get(k, k)}: {v}" for k, v in (q or {}).items())
        groups.setdefault(text, []).append(str(fid))
    return " | ".join((f"{', '.join(f)}: " if len(src) > 1 else "") + text for text, f in groups.items())


def _used_share_text(share: dict) -> str:
    """' N of M recorded rows are used (...)' from the usable_share metadata ('' if absent)."""
    if not share or not share.get("recorded"):
        return ""
    low = [f"{c} {100.0 * v['share']:.1f} %" for c, v in share.get("by_channel", {}).items()
           if v.get("used", 0) < share["recorded"]]
    return (f" {share['used']} of {share['recorded']} recorded rows are used "
            f"({100.0 * share['share']:.2f} %: every channel a measurement, or a held value between its "
            f"sensor's updates)" + (f"; channels below 100 %: {', '.join(low)}" if low else "") + ".")


def _s_preprocessing(run: _Run) -> str:
    path = run.dir / "preprocessed.parquet"
    meta = _meta(path) if path.is_file() else {}
    if not meta:
        return _note("No preprocessed.parquet (or no preprocessing metadata) in this run folder: the preprocessing "
                     "stage has not run or its output was removed.")
    p = "aerosid.preprocess."
    counts = _jmeta(meta, p + "summary_counts", {})
    by_ch = _jmeta(meta, p + "flag_counts_by_channel", {})
    longest = _jmeta(meta, p + "longest_gap_s", None)
    long_gaps = _jmeta(meta, p + "long_gaps", [])
    params = _jmeta(meta, p + "params", {})
    rate = _jmeta(meta, p + "nominal_rate_hz", None)
    inferred = _jmeta(meta, p + "rate_inferred", None)
    grid = counts.get("grid")
    out = []
    usable = counts.get("usable")
    share = f" ({100.0 * usable / grid:.2f} % of the grid)" if _finite(usable) and grid else ""
    out.append(_p(f"{counts.get('raw', '?')} raw rows were put on a uniform {_num(rate, '.6g')} Hz grid "
                  f"({'rate inferred from the timestamps' if inferred else 'rate given'}) of {grid} rows; "
                  f"{counts.get('inserted', '?')} rows were inserted where no raw row arrived. "
                  f"{usable} rows are usable in every channel{share}."
                  + _used_share_text(_jmeta(meta, p + "usable_share", {}))))
    gap_txt = (f"Longest all-channel gap: {_num(longest, '.3f')} s. Gaps longer than "
               f"{_num(params.get('max_interp_gap_s'), 'g')} s are not interpolated; the flight is split there "
               f"into segments: " + (", ".join(f"{_num(a, '.3f')}–{_num(b, '.3f')} s" for a, b in long_gaps)
                                     if long_gaps else "none") + ".")
    out.append(_p(gap_txt))
    kinds = [k for k in FLAG_MEANINGS if k in counts] + [k for k in counts if k not in FLAG_MEANINGS and
                                                         k not in ("raw", "grid", "inserted", "usable")]
    rows = [(k, counts.get(k, 0), FLAG_MEANINGS.get(k, "")) for k in kinds]
    out.append(_table(["flag", "rows with it (any channel)", "meaning"], rows, id="preprocess-flags",
                      caption="Samples flagged, by kind"))
    if by_ch:
        nz = [k for k in kinds if any(int(c.get(k, 0) or 0) for c in by_ch.values())]
        if nz:
            out.append(_table(["channel", *nz], [(ch, *(c.get(k, 0) for k in nz)) for ch, c in by_ch.items()],
                              cls="compact", caption="Flagged samples per channel (kinds that occur)"))
    return "\n".join(out)


_NOTE_ROW = re.compile(r"^(ax|ay|az|p|q|r)\s+(\S+)((?:\s+\S+){5,6})\s*$")
#: The columns of a channel's row in the smoother's summary after its unit: before the white
#: floor was added (2026-11-28), and since.
_NOTE_COLUMNS = {5: ("used", "dispersion", "seed", "nis_filter", "nis_smoother"),
                 6: ("used", "dispersion", "seed", "floor", "nis_filter", "nis_smoother")}


def _nis_from_note(note: str | None) -> dict:
    """Per-channel rows of the smoother's own summary (its Table-2 text), when recorded:
    {channel: {column: value}} (columns of _NOTE_COLUMNS; a NaN floor reads as NaN)."""
    rows = {}
    for line in (note or "").splitlines():
        m = _NOTE_ROW.match(line.strip())
        if m:
            tokens = m.group(3).split()
            try:
                rows[m.group(1)] = dict(zip(_NOTE_COLUMNS[len(tokens)], map(float, tokens)))
            except ValueError:
                continue
    return rows


def _segment_note(run: _Run, seg: str) -> str | None:
    for d in run.run.get("segments_ok") or []:
        if d.get("segment") == seg and d.get("note"):
            return d["note"]
    for rec in reversed(run.ledger):
        if rec.get("stage") == "smooth" and rec.get("segment") == seg and rec.get("status") == "ok" and rec.get("note"):
            return rec["note"]
    return None


def _segment_failure(run: _Run, seg: str) -> str | None:
    for d in run.run.get("segments_failed") or []:
        if d.get("segment") == seg:
            return str(d.get("error") or "failed")
    latest = None
    for rec in run.ledger:
        if rec.get("stage") == "smooth" and rec.get("segment") == seg:
            latest = rec
    if latest is not None and latest.get("status") == "failed":
        return str(latest.get("error") or "failed")
    return None


def _s_segments(run: _Run) -> str:
    ids = run.segment_ids()
    if not ids:
        return _note("No segments: the smoothing stage has not run in this folder.")
    out = []
    status_rows = []
    details = []
    pre = run.frame("preprocessed.parquet")
    for k, seg in enumerate(ids):
        path = run.dir / "segments" / seg / "smoothed.parquet"
        failure = _segment_failure(run, seg)
        if failure is not None or not path.is_file():
            rec = next((r for r in reversed(run.ledger) if r.get("stage") == "smooth" and r.get("segment") == seg),
                       {})
            span = ((rec.get("params") or {}).get("segment") or {})
            status_rows.append((seg, _span(span.get("t_start_s"), span.get("t_end_s")), "—", "failed" if failure
                                else "missing", failure or f"{path.relative_to(run.dir)} is missing"))
            details.append(f'<h3 id={_q(f"segment-{seg}")}>Segment {_e(seg)}</h3>' + _note(
                f"No smoothed data for this segment: {failure or 'the file is missing'}. It is left out of the "
                "flight data and the regression; the other segments are used."))
            continue
        try:
            sm = pd.read_parquet(path)
        except Exception as exc:  # pyarrow raises several types
            status_rows.append((seg, "—", "—", "unreadable", f"{type(exc).__name__}: {exc}"))
            continue
        t = sm["t_s"].to_numpy(float)
        status_rows.append((seg, _span(t[0], t[-1]) if t.size else "—", len(sm), "ok", ""))
        details.append(_segment_detail(run, seg, sm, _meta(path), pre, k))
    out.append(_table(["segment", "time span", "samples", "status", "note"], status_rows, id="segments-status"))
    out.extend(details)
    return "\n".join(out)


def _segment_detail(run: _Run, seg: str, sm: pd.DataFrame, meta: dict, pre: pd.DataFrame | None, k: int) -> str:
    nis = _jmeta(meta, "aerosid.nis", {}) or {}
    band = nis.get("band") or [None, None]
    R = nis.get("R_sigma") or []
    parsed = _nis_from_note(_segment_note(run, seg))
    out = [f'<h3 id={_q(f"segment-{seg}")}>Segment {_e(seg)}</h3>']
    nf = sm["nis_filter"].to_numpy(float) if "nis_filter" in sm else np.array([])
    ns = sm["nis_smoother"].to_numpy(float) if "nis_smoother" in sm else np.array([])
    n_upd = int(sm["updated"].sum()) if "updated" in sm else None
    inside = (_finite(nis.get("mean_nis_filter")) and _finite(band[0]) and _finite(band[1])
              and band[0] <= nis["mean_nis_filter"] <= band[1])
    out.append(_p(
        f"{len(sm)} samples, {n_upd if n_upd is not None else '?'} with a measurement update. The normalised "
        f"innovation squared (NIS) checks that the filter's noise model matches the data: its mean should lie in "
        f"the chi-square band {_num(band[0], '.3f')}–{_num(band[1], '.3f')}. Mean NIS: filter "
        f"{_num(nis.get('mean_nis_filter'), '.3f')}, smoother {_num(nis.get('mean_nis_smoother'), '.3f')} "
        f"({'inside' if inside else 'outside'} the band)."))
    headers = ["channel", "unit", "σ used (R)"]
    floor = parsed and any("floor" in v for v in parsed.values())
    if parsed:
        headers += ["dispersion", "seed rule Δy/3"] + (["white floor (σ near Nyquist)"] if floor else [])
        headers += ["NIS EKF", "NIS smoother"]
    headers += ["gated samples"]
    rows = []
    for j, ch in enumerate(MEAS_UNITS):
        row = [ch, MEAS_UNITS[ch], R[j] if j < len(R) else None]
        if parsed:
            vals = parsed.get(ch, {})
            row += [_num(vals.get("dispersion"), ".4g"), _num(vals.get("seed"), ".4g")]
            row += [_num(vals.get("floor"), ".4g")] if floor else []
            row += [_num(vals.get("nis_filter"), ".3f"), _num(vals.get("nis_smoother"), ".3f")]
        row.append(int(sm[f"gated_{ch}"].sum()) if f"gated_{ch}" in sm else "—")
        rows.append(row)
    total = ["total (mean NIS)", "", ""]
    if parsed:
        total += ["", ""] + ([""] if floor else [])
        total += [_num(nis.get("mean_nis_filter"), ".3f"), _num(nis.get("mean_nis_smoother"), ".3f")]
    total += [""]
    rows.append(_H('<tr class="total">' + "".join(f"<td{_align(c) if c else ''}>{_cell(c)}</td>" for c in total)
                   + "</tr>"))
    cap = "Filter/smoother consistency (seed Table 2 style)"
    out.append(_table(headers, rows, cls="nis", caption=cap))
    if nf.size and np.isfinite(nf).any():
        out.append(_p(f"Per-sample NIS (all channels): filter median {_num(np.nanmedian(nf), '.3g')}, 95th "
                      f"percentile {_num(np.nanpercentile(nf, 95), '.3g')}; smoother median "
                      f"{_num(np.nanmedian(ns), '.3g') if ns.size and np.isfinite(ns).any() else '—'}."))
    if {"q_rad_s", "sigma_q_rad_s"} <= set(sm.columns):
        out.append(_q_plot(seg, sm, pre, k))
    return "\n".join(out)


def _q_plot(seg: str, sm: pd.DataFrame, pre: pd.DataFrame | None, k: int) -> str:
    d = 180 / math.pi
    t = sm["t_s"].to_numpy(float)
    q = sm["q_rad_s"].to_numpy(float) * d
    s = sm["sigma_q_rad_s"].to_numpy(float) * d
    th = _thin(len(t))
    fig, (ax,) = _figure((9, 3.0))
    if pre is not None and "q_rad_s_clean" in pre and len(t):
        rows = pre[pre["t_s"].between(t[0], t[-1])]
        tt, qq = _gaps(rows["t_s"].to_numpy(float)[_thin(len(rows))], rows["q_rad_s_clean"].to_numpy(float)[
            _thin(len(rows))] * d)
        ax.plot(tt, qq, "-", color="0.7", lw=0.5, label="measured q (preprocessed)")
    ax.fill_between(t[th], (q - 2 * s)[th], (q + 2 * s)[th], color="tab:blue", alpha=0.3, lw=0, label="±2σ")
    ax.plot(t[th], q[th], "-", color="tab:blue", lw=0.9, label="smoothed q")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("q [deg/s]")
    ax.legend(loc="upper right", fontsize=8)
    return _svg(fig, f"q{k}", f"Segment {seg}: smoothed pitch rate q with ±2σ band (deg/s), over the preprocessed "
                             "measurement")


