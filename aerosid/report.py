"""A self-contained HTML report of one run folder (``RUN_DIR/report.html``).

    >>> from aerosid.report import build_report, write_report
    >>> write_report("runs/reference/run")                      # -> runs/reference/run/report.html
    >>> write_report(run_dir, diagnosis=diag, truth=json.load(open("truth.json")))

The document holds everything an engineer hands to a colleague: what was
processed (flight, vehicle, telemetry file and its SHA-256, code version),
preprocessing, the filter/smoother consistency per segment, the coefficients
(seed Table 3 style), measured vs model per channel, the diagnosis and the model
version history.  Plots are matplotlib SVG with the text drawn as paths, inlined
in the page; there is no script, no stylesheet, font or image to fetch: the file
opens the same on an air-gapped machine.  Sections without data (no diagnosis
yet, a failed segment, no model versions) say so.  Read only: the report never
computes a new diagnosis or fit.  See ``docs/report.md``.
"""
from __future__ import annotations

import html
import io
import json
import math
import re
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

__all__ = ["build_report", "write_report", "REPORT_NAME"]

REPORT_NAME = "report.html"
CHANNELS = ("CN", "Cm", "CY", "Cn", "Cl")
MEAS_UNITS = {"ax": "m/s^2", "ay": "m/s^2", "az": "m/s^2", "p": "rad/s", "q": "rad/s", "r": "rad/s"}
_MAX_POINTS = 4000  # per plotted series; longer series are thinned (every k-th sample)
_RC = {"svg.fonttype": "path", "svg.hashsalt": "aerosid-report", "path.simplify": True,
       "font.size": 9, "axes.grid": True, "grid.alpha": 0.3}

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


# --------------------------------------------------------------------------- HTML helpers
class _H(str):
    """Text that is already HTML (never escaped again)."""


def _e(x) -> str:
    return html.escape("" if x is None else str(x), quote=True)


def _finite(x) -> bool:
    try:
        return x is not None and not isinstance(x, bool) and math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def _num(x, fmt: str = ".4g") -> str:
    return format(float(x), fmt) if _finite(x) else "—"


def _cell(v) -> str:
    if isinstance(v, _H):
        return v
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        return _e(_num(v))
    if isinstance(v, (int, np.integer)):
        return _e(str(int(v)))
    return _e(v)


_NUMERIC = re.compile(r"^(?:[-+]?(?:\d[\d,]*\.?\d*|\.\d+)(?:e[-+]?\d+)?(?: %)?|\[.*\]|[×x][\d.]+.*)$")


def _align(v) -> str:
    """' class="n"' for a number (right-aligned), ' class="c"' for a dash (centred), '' for text."""
    if isinstance(v, (_H, bool, np.bool_)):
        return ""
    if isinstance(v, (int, float, np.integer, np.floating)):
        return ' class="n"' if _finite(v) else ' class="c"'
    text = str(v).strip() if isinstance(v, str) else ""
    if text in ("—", "nan"):
        return ' class="c"'
    return ' class="n"' if text and _NUMERIC.match(text) else ""


def _table(headers, rows, *, id: str | None = None, cls: str = "", caption: str | None = None) -> str:
    """An HTML table; numbers right-aligned, text left-aligned (a header follows its
    column).  Wide tables scroll inside their own box, not the page."""
    plain = [r for r in rows if not isinstance(r, _H)]
    num_col = [any(j < len(r) and _align(r[j]) == ' class="n"' for r in plain) for j in range(len(headers))]
    out = [f'<div class="scroll"><table{f" id={_q(id)}" if id else ""}{f" class={_q(cls)}" if cls else ""}>']
    if caption:
        out.append(f"<caption>{_e(caption)}</caption>")
    out.append("<thead><tr>" + "".join(f'<th{_align(1.0) if num_col[j] else ""}>{_cell(h)}</th>'
                                       for j, h in enumerate(headers)) + "</tr></thead><tbody>")
    for row in rows:
        if isinstance(row, _H):  # a complete pre-built <tr>
            out.append(row)
        else:
            out.append("<tr>" + "".join(f"<td{_align(c)}>{_cell(c)}</td>" for c in row) + "</tr>")
    out.append("</tbody></table></div>")
    return "\n".join(out)


def _q(s: str) -> str:
    return '"' + _e(s) + '"'


def _p(text: str, cls: str = "") -> str:
    return f'<p{f" class={_q(cls)}" if cls else ""}>{_e(text)}</p>'


def _note(text: str) -> str:
    return _p(text, "note")


def _heat(ratio) -> str:
    """Background colour of a residual-RMS ratio cell: white at 1, red above, blue below."""
    if not _finite(ratio):
        return "#f4f4f4"
    r = float(ratio)
    if r >= 1:
        t = min((r - 1) / 1.5, 1.0)
        return f"rgb(255,{int(255 - 140 * t)},{int(255 - 140 * t)})"
    t = min((1 - r) / 0.8, 1.0)
    return f"rgb({int(255 - 60 * t)},{int(255 - 30 * t)},255)"


# --------------------------------------------------------------------------- SVG plots
def _svg(fig, key: str, label: str) -> str:
    """The figure as an inline <svg> element: text as paths (no fonts), no metadata,
    no namespace URLs, ids prefixed with `key` so several plots share one page."""
    import matplotlib

    buf = io.StringIO()
    with matplotlib.rc_context(_RC):
        fig.savefig(buf, format="svg", bbox_inches="tight")
    text = buf.getvalue()
    text = text[text.index("<svg"):]
    text = re.sub(r"<metadata>.*?</metadata>", "", text, flags=re.S)
    text = re.sub(r'<style type="text/css">.*?</style>', "", text, flags=re.S)
    text = re.sub(r'\s+xmlns(:\w+)?="[^"]*"', "", text)
    ids = set(re.findall(r'\bid="([^"]+)"', text))
    text = re.sub(r'(\bid="|href="#|url\(#)([^")]+)',
                  lambda m: m.group(1) + (f"{key}-{m.group(2)}" if m.group(2) in ids else m.group(2)), text)
    text = text.replace("<svg", f'<svg class="plot" role="img" aria-label={_q(label)}', 1)
    return f'<figure>{text}<figcaption>{_e(label)}</figcaption></figure>'


def _figure(figsize, nrows: int = 1, height_ratios=None, ncols: int = 1):
    import matplotlib
    from matplotlib.figure import Figure  # no pyplot: no global state, safe in worker threads

    with matplotlib.rc_context(_RC):
        fig = Figure(figsize=figsize, layout="constrained")
        axes = fig.subplots(nrows, ncols, sharex=ncols == 1, squeeze=False,
                            gridspec_kw={"height_ratios": height_ratios} if height_ratios else None).ravel()
    return fig, axes


def _thin(n: int) -> slice:
    return slice(None, None, max(1, math.ceil(n / _MAX_POINTS)))


def _gaps(t: np.ndarray, *ys: np.ndarray):
    """NaN between samples further apart than 5 median steps (no line across a gap)."""
    t = np.asarray(t, float)
    if t.size < 3:
        return (t, *ys)
    dt = np.diff(t)
    pos = dt[dt > 0]
    cut = np.flatnonzero((dt > 5 * np.median(pos)) | (dt <= 0)) if pos.size else np.array([], int)
    if cut.size == 0:
        return (t, *ys)
    out_t = np.insert(t, cut + 1, np.nan)
    return (out_t, *(np.insert(np.asarray(y, float), cut + 1, np.nan) for y in ys))


# --------------------------------------------------------------------------- reading the run folder
def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _read_ledger(path: Path) -> list[dict]:
    out = []
    try:
        lines = path.read_text().splitlines()
    except OSError:
        return out
    for line in lines:
        try:
            rec = json.loads(line)
        except ValueError:
            continue
        if isinstance(rec, dict):
            out.append(rec)
    return out


def _meta(path: Path) -> dict:
    from aerosid.io import read_parquet_metadata

    try:
        return read_parquet_metadata(path)
    except Exception:  # pyarrow raises several types for unreadable files
        return {}


def _jmeta(meta: dict, key: str, default=None):
    try:
        return json.loads(meta[key])
    except (KeyError, ValueError, TypeError):
        return default


@dataclass
class _Run:
    dir: Path
    run: dict = field(default_factory=dict)
    ledger: list = field(default_factory=list)
    errors: list = field(default_factory=list)  # problems met while reading (shown in the report)
    _cache: dict = field(default_factory=dict)

    @classmethod
    def load(cls, run_dir: Path) -> "_Run":
        r = cls(Path(run_dir))
        rj = r.dir / "run.json"
        if rj.is_file():
            doc = _read_json(rj)
            if isinstance(doc, dict):
                r.run = doc
            else:
                r.errors.append(f"{rj}: not valid JSON")
        r.ledger = _read_ledger(r.dir / "ledger.jsonl")
        return r

    def frame(self, name: str) -> pd.DataFrame | None:
        """A Parquet file of the run (None when absent; an unreadable file is noted)."""
        if name not in self._cache:
            path = self.dir / name
            frame = None
            if path.is_file():
                try:
                    frame = pd.read_parquet(path)
                except Exception as exc:  # pyarrow raises several types
                    self.errors.append(f"{path}: cannot read ({type(exc).__name__}: {exc})")
            self._cache[name] = frame
        return self._cache[name]

    def unreadable(self, name: str) -> str | None:
        """The reading error of a file of the run, if it exists but could not be read."""
        return next((e for e in self.errors if e.startswith(str(self.dir / name) + ":")), None)

    @property
    def flight(self) -> str:
        if self.run.get("flight"):
            return str(self.run["flight"])
        for rec in reversed(self.ledger):
            if rec.get("flight"):
                return str(rec["flight"])
        return self.dir.name

    @property
    def vehicle(self) -> str:
        return str(self.run.get("vehicle") or (self.run.get("job") or {}).get("vehicle") or "seed-rlv")

    def last(self, stage: str, segment: str | None = None, statuses=("ok", "reused")) -> dict | None:
        for rec in reversed(self.ledger):
            if rec.get("stage") == stage and rec.get("status") in statuses and \
                    (segment is None or rec.get("segment") == segment):
                return rec
        return None

    def segment_ids(self) -> list[str]:
        ids = list(self.run.get("segments") or [])
        seg_root = self.dir / "segments"
        if seg_root.is_dir():
            ids += [p.name for p in sorted(seg_root.iterdir()) if (p / "smoothed.parquet").is_file()]
        ids += [r.get("segment") for r in self.ledger if r.get("stage") == "smooth" and r.get("segment")]
        return list(dict.fromkeys(i for i in ids if i))


# --------------------------------------------------------------------------- inputs
def _diagnosis_inputs(run: _Run, diagnosis) -> tuple[dict | None, object | None, str]:
    """(the diagnosis JSON document, the Diagnosis object if given, where it came from)."""
    if diagnosis is None:
        path = run.dir / "diagnosis.json"
        if not path.is_file():
            return None, None, ""
        doc = _read_json(path)
        if not isinstance(doc, dict):
            run.errors.append(f"{path}: not valid JSON; the diagnosis is left out")
            return None, None, ""
        return doc, None, str(path.name)
    if isinstance(diagnosis, (str, Path)):
        doc = _read_json(Path(diagnosis))
        if not isinstance(doc, dict):
            raise ValueError(f"{diagnosis}: not a diagnosis JSON document")
        return doc, None, str(diagnosis)
    if isinstance(diagnosis, dict):
        return diagnosis, None, "the diagnosis given"
    if hasattr(diagnosis, "to_json") and hasattr(diagnosis, "channels"):
        return diagnosis.to_json(), diagnosis, "the diagnosis given (computed in memory)"
    raise TypeError(f"diagnosis must be a Diagnosis, a diagnosis.json dict or a path, not {type(diagnosis).__name__}")


def _truth_coefficients(truth) -> dict:
    if truth is None:
        return {}
    if isinstance(truth, (str, Path)):
        truth = json.loads(Path(truth).read_text())
    if not isinstance(truth, dict):
        raise TypeError(f"truth must be a truth.json dict or a path, not {type(truth).__name__}")
    coeffs = truth.get("coefficients", truth)
    return {str(k): float(v) for k, v in coeffs.items() if _finite(v)}


# --------------------------------------------------------------------------- sections
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
    if run.errors:
        body += "".join(_note(e) for e in run.errors)
    return body


def _flights(run: _Run) -> list[_Run] | None:
    """The manoeuvres of a pooled run (run.json ``flights``), each as a run of its own
    folder ``flights/<id>/`` with its ledger records; None for a one-flight run."""
    flights = run.run.get("flights")
    if not isinstance(flights, list) or not flights:
        return None
    return [_Run(run.dir / "flights" / str(fs.get("flight")), fs,
                 [r for r in run.ledger if r.get("flight") == fs.get("flight")]) for fs in flights]


def _per_flight(run: _Run, section: Callable[[_Run], str]) -> str:
    """A per-flight section once per manoeuvre of a pooled run."""
    subs = _flights(run)
    if subs is None:
        return section(run)
    return "\n".join(f'<h3 id={_q("manoeuvre-" + sub.flight)}>Manoeuvre {_e(sub.flight)}</h3>\n' + section(sub)
                     for sub in subs)


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


_NOTE_ROW = re.compile(r"^(ax|ay|az|p|q|r)\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)\s*$")


def _nis_from_note(note: str | None) -> dict:
    """Per-channel rows of the smoother's own summary (its Table-2 text), when recorded."""
    rows = {}
    for line in (note or "").splitlines():
        m = _NOTE_ROW.match(line.strip())
        if m:
            try:
                rows[m.group(1)] = [float(m.group(i)) for i in range(3, 8)]
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


def _span(a, b) -> str:
    if not (_finite(a) and _finite(b)):
        return "—"
    return f"{round(float(a), 2) + 0.0:.2f}–{round(float(b), 2) + 0.0:.2f} s"


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
    if parsed:
        headers += ["dispersion", "seed rule Δy/3", "NIS EKF", "NIS smoother"]
    headers += ["gated samples"]
    rows = []
    for j, ch in enumerate(MEAS_UNITS):
        row = [ch, MEAS_UNITS[ch], R[j] if j < len(R) else None]
        if parsed:
            vals = parsed.get(ch, [None] * 5)
            row += [_num(vals[1], ".4g"), _num(vals[2], ".4g"), _num(vals[3], ".3f"), _num(vals[4], ".3f")]
        row.append(int(sm[f"gated_{ch}"].sum()) if f"gated_{ch}" in sm else "—")
        rows.append(row)
    total = ["total (mean NIS)", "", ""]
    if parsed:
        total += ["", "", _num(nis.get("mean_nis_filter"), ".3f"), _num(nis.get("mean_nis_smoother"), ".3f")]
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


def _s_coefficients(run: _Run, truth: dict) -> str:
    from aerosid.identify import ANGLE_TERMS

    table = run.frame("coefficients.parquet")
    if table is None or table.empty:
        return _note(run.unreadable("coefficients.parquet") or
                     "No coefficients.parquet: the regression has not run (or every segment failed).")
    has_truth = bool(truth)
    headers = ["coefficient", "per", "preflight", "estimate", "σ corrected", "σ OLS", "95 % interval"]
    if has_truth:
        headers += ["truth", "error %", "truth in interval"]
    ncol = len(headers)
    rows = []
    for channel, g in table.groupby("channel", sort=False):
        first = g.iloc[0]
        head = (f"{channel}: F = {_num(first.get('f_stat'), ',.0f')} (corrected "
                f"{_num(first.get('f_stat_corrected'), ',.1f')}), R² = {_num(first.get('r2'), '.4f')}, PSE = "
                f"{_num(first.get('pse'), '.3g')}, condition number {_num(first.get('condition_number'), '.1f')}, "
                f"N = {first.get('n_obs', '?')} (effective {_num(first.get('n_eff'), '.0f')}), residual RMS "
                f"{_num(first.get('rms_residual'), '.3g')}")
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
                cells = [str(r["coefficient"]), per, _sc(ref, k),
                         _H(f'<span class="na">not identifiable (no excitation in {_e(expr or "its term")})</span>'),
                         "", "", ""]
                if has_truth:
                    cells += [_sc(tv, k), "—", "—"]
                rows.append(cells)
                continue
            lo, hi = r.get("ci_low"), r.get("ci_high")
            cells = [str(r["coefficient"]), per, _sc(ref, k), _sc(est, k), _sc(r.get("std_error"), k, ".2g"),
                     _sc(r.get("std_error_ols"), k, ".2g"), f"[{_num(_k(lo, k), '.5g')}, {_num(_k(hi, k), '.5g')}]"]
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
    intro = _p("Moments about the CG. Angle slopes are printed per degree (pitch and yaw fin slopes per degree "
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


# --------------------------------------------------------------------------- measured vs model
def _comparisons(run: _Run, diag) -> tuple[dict, str]:
    """channel -> dict(t, measured, model, residual, flagged windows); and where the model came from."""
    if diag is not None:
        out = {}
        for ch, rep in diag.channels.items():
            out[ch] = {"t": np.asarray(rep.t_s, float), "measured": np.asarray(rep.measured, float),
                       "model": np.asarray(rep.model, float), "residual": np.asarray(rep.residual, float),
                       "flagged": [(w.t_start_s, w.t_end_s) for w in rep.windows if w.flagged],
                       "rms": float(rep.fit.rms_residual), "r2": float(rep.fit.r2)}
        return out, "the diagnosed model (its flagged time windows are shaded)"
    fd = run.frame("flight_data.parquet")
    table = run.frame("coefficients.parquet")
    if fd is None or table is None or table.empty or fd.empty:
        return {}, ""
    from aerosid.expressions import evaluate
    from aerosid.identify import mach_window_mask
    from aerosid.models import signals_from_flight_data
    from aerosid.vehicle import load_vehicle

    veh = load_vehicle(run.vehicle)
    half = (run.run.get("job") or {}).get("mach_half_width", 0.5)
    fd = fd.sort_values(["flight", "t_s"], kind="stable").reset_index(drop=True)
    fd = fd.loc[mach_window_mask(fd["mach"].to_numpy(float), veh.mach_reference, half)].reset_index(drop=True)
    if fd.empty:
        return {}, ""
    sig = signals_from_flight_data(fd, veh.length_pitch_m, veh.length_lateral_m)
    n = len(fd)
    out = {}
    for ch, g in table.groupby("channel", sort=False):
        if ch not in fd:
            continue
        model = np.zeros(n)
        for _, r in g.iterrows():
            if _finite(r.get("estimate")) and r.get("expression"):
                model += float(r["estimate"]) * np.asarray(evaluate(str(r["expression"]), sig, n), float)
        y = fd[ch].to_numpy(float)
        out[ch] = {"t": fd["t_s"].to_numpy(float), "measured": y, "model": model, "residual": y - model,
                   "flagged": [], "rms": float(g.iloc[0].get("rms_residual", np.nan)),
                   "r2": float(g.iloc[0].get("r2", np.nan))}
    return out, "the coefficients of coefficients.parquet (Mach window of the fit)"


def _s_comparison(run: _Run, diag) -> str:
    try:
        comps, source = _comparisons(run, diag)
    except Exception as exc:  # e.g. a vehicle file no longer available
        return _note(f"Measured vs model could not be computed: {type(exc).__name__}: {exc}")
    if not comps:
        bad = [e for e in (run.unreadable("flight_data.parquet"), run.unreadable("coefficients.parquet")) if e]
        return _note("; ".join(bad) if bad else
                     "No flight data or no coefficients in this run folder: nothing to compare.")
    out = [_p(f"Each channel's flight-derived (measured) coefficient against the model output, over time, with the "
              f"residual (measured − model) below. Model: {source}. A good model leaves a residual without "
              "structure; steps, drifts or oscillations in it point at a missing effect.")]
    for i, ch in enumerate([c for c in CHANNELS if c in comps] + [c for c in comps if c not in CHANNELS]):
        c = comps[ch]
        out.append(f'<h3 id={_q("cmp-" + ch)}>{_e(ch)}</h3>')
        out.append(_p(f"Residual RMS {_num(c['rms'], '.3g')}, R² {_num(c['r2'], '.5f')}, {len(c['t'])} samples."))
        fig, (a1, a2) = _figure((9, 4.2), 2, [2, 1])
        th = _thin(len(c["t"]))
        t, y, m, res = _gaps(c["t"][th], c["measured"][th], c["model"][th], c["residual"][th])
        a1.plot(t, y, "-", color="tab:blue", lw=0.7, label="measured (flight-derived)")
        a1.plot(t, m, "-", color="tab:orange", lw=1.0, label="model")
        a1.set_ylabel(ch)
        a1.legend(loc="best", fontsize=8)
        a2.plot(t, res, "-", color="tab:green", lw=0.6)
        a2.axhline(0, color="0.3", lw=0.6)
        for a, b in c["flagged"]:
            a2.axvspan(a, b, color="tab:red", alpha=0.15)
        a2.set_ylabel("residual")
        a2.set_xlabel("t [s]")
        out.append(_svg(fig, f"cmp{i}", f"{ch}: measured vs model (top) and residual (bottom) against time"))
    return "\n".join(out)


# --------------------------------------------------------------------------- diagnosis
def _s_diagnosis(doc: dict | None, diag, source: str, run: _Run) -> str:
    if doc is None:
        return _note("No diagnosis yet for this run. Run `aerosid diagnose RUN_DIR` (it writes diagnosis.json), "
                     "then regenerate the report.")
    out = []
    model = doc.get("model")
    out.append(_p(f"Source: {source}" + (f"; model diagnosed: {model}" if model else "") +
                  f"; {doc.get('n_samples', '?')} samples in Mach "
                  f"{_num((doc.get('mach_window') or [None])[0], '.2f')}–"
                  f"{_num((doc.get('mach_window') or [None, None])[-1], '.2f')}."))
    out.append(f'<div class="message" id="diagnosis-message">{_e(doc.get("message", "(no message)"))}</div>')
    rule = (doc.get("rule") or {}).get("text")
    if rule:
        out.append(_p(f"Rule for 'significant': {rule}."))
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
    out.append(_windows(doc.get("time_windows") or []))
    out.append(_regimes(doc, diag))
    out.append("<h3 id=\"whiteness\">Whiteness of the residuals</h3>")
    out.append(_whiteness(doc.get("whiteness") or {}))
    return "\n".join(out)


def _pct(x, fmt: str) -> str:
    return format(100 * float(x), fmt) + " %" if _finite(x) else "—"


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


def _regimes(doc: dict, diag) -> str:
    if diag is not None:  # every bin of every variable
        out = [_p("Residual map by regime: the samples are cut into 8 quantile bins of each variable; each cell is "
                  "the residual RMS in that bin relative to the channel's (flagged in bold: ≥ 1.5× with ≥ 30 "
                  "samples). On a flight where Mach falls steadily, a Mach bin is also a time span.")]
        for ch, rep in diag.channels.items():
            by_var: dict = {}
            for b in rep.regimes:
                by_var.setdefault((b.variable, b.unit), []).append(b)
            nb = max((len(v) for v in by_var.values()), default=0)
            rows = []
            for (var, unit), bins in by_var.items():
                cells = [f"<th>{_e(var)} [{_e(unit)}]</th>"]
                for b in bins:
                    title = f"{var} {b.lo:.4g}..{b.hi:.4g} {unit}, n {b.n}, RMS {b.rms:.3g}, mean {b.mean:.3g}"
                    cls = ' class="flagged"' if b.flagged else ""
                    cells.append(f'<td{cls} style="background:{_heat(b.rms_ratio)}" title={_q(title)}>'
                                 f"×{_e(_num(b.rms_ratio, '.2f'))}<br><small>{_e(f'{b.lo:.3g}..{b.hi:.3g}')}"
                                 "</small></td>")
                cells += ["<td></td>"] * (nb - len(bins))
                rows.append(_H("<tr>" + "".join(cells) + "</tr>"))
            out.append(_table(["variable"] + [f"bin {j + 1}" for j in range(nb)], rows, cls="heat regimes",
                              caption=f"{ch}: residual RMS ratio by regime bin (low → high)"))
        return "\n".join(out)
    regs = doc.get("regimes") or []
    if not regs:
        return _note("No regime statistics in the diagnosis.")
    rows = [(r.get("channel"), r.get("variable"), f"{_num(r.get('lo'), '.4g')} .. {_num(r.get('hi'), '.4g')} "
             f"{r.get('unit', '')}", r.get("n"), _num(r.get("rms"), ".3g"),
             _H(f'<span style="background:{_heat(r.get("rms_ratio"))}">×{_e(_num(r.get("rms_ratio"), ".2f"))}</span>'),
             bool(r.get("flagged"))) for r in regs]
    return (_p("The worst regime bins per channel (from diagnosis.json, which keeps the 3 worst of each): residual "
               "RMS in the bin relative to the channel's. Pass the Diagnosis object to build_report for the full "
               "map.")
            + _table(["channel", "variable", "bin", "samples", "RMS", "ratio", "flagged"], rows, id="regimes-worst"))


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


# --------------------------------------------------------------------------- versions and audit
def _s_versions(run: _Run) -> str:
    from aerosid.versions import history

    h = history(run.dir)
    if not h.versions:
        return _note("No model versions yet. `aerosid fit RUN_DIR --model SPEC` stores v001 (the default models) "
                     "and each new model as the next version.")
    tab = h.table()
    chans = [c for c in CHANNELS if f"rms_{c}" in tab] + [c[4:] for c in tab.columns if c.startswith("rms_")
                                                          and c[4:] not in CHANNELS]
    rows = [[r["version"], r["parent"] or "—", r["changes"], r["note"], *(r[f"rms_{c}"] for c in chans)]
            for _, r in tab.iterrows()]
    out = [_p("Every fit is kept as an immutable version with its parent. Changes are relative to the parent; the "
              "numbers are the residual RMS per channel (lower is better)."),
           _table(["version", "parent", "changes", "note", *(f"RMS {c}" for c in chans)], rows, id="versions-table")]
    data = h.plot_data()
    fig, (ax, rel) = _figure((9, 3.2), ncols=2)
    for ch, g in data.groupby("channel", sort=False):
        y = g["rms"].to_numpy(float)
        y = np.where(y > 0, y, np.nan)
        ax.plot(g["number"], y, "o-", label=ch)
        rel.plot(g["number"], 100 * y / y[0] if _finite(y[0]) else y * np.nan, "o-", label=ch)
    ax.set_yscale("log")
    ax.set_ylabel("residual RMS")
    rel.set_ylabel(f"% of {h.versions[0].id}")
    rel.axhline(100, color="0.4", lw=0.6)
    for a in (ax, rel):
        a.set_xlabel("model version")
        a.set_xticks(sorted(set(int(v) for v in data["number"])))
    rel.legend(fontsize=8, loc="best")
    out.append(_svg(fig, "versions", "Residual RMS per channel against model version: absolute (log scale, left) and relative to the "
                                   "first version (right)"))
    return "\n".join(out)


def _s_audit(run: _Run) -> str:
    if not run.ledger:
        return _note("No ledger.jsonl in this run folder.")
    latest: dict = {}
    for rec in run.ledger:
        if rec.get("stage") in (None, "inbox"):
            continue
        latest[(rec.get("stage"), rec.get("segment") or "")] = rec
    rows = [(rec.get("time_utc", ""), stage, seg or "—", rec.get("status", ""), _num(rec.get("duration_s"), ".2f"),
             rec.get("rows_in"), rec.get("rows_out"), rec.get("flagged_rows"),
             ", ".join(str(o.get("sha256", ""))[:12] for o in rec.get("outputs") or []) or "—",
             rec.get("error") or "") for (stage, seg), rec in latest.items()]
    return (_p(f"The latest ledger record of each stage ({len(run.ledger)} records in ledger.jsonl). "
               "`aerosid audit FILE` traces any output back to the raw telemetry.")
            + _table(["time (UTC)", "stage", "segment", "status", "duration [s]", "rows in", "rows out", "flagged",
                      "output SHA-256 (first 12)", "error"], rows, id="audit-table", cls="compact"))


# --------------------------------------------------------------------------- document
_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;margin:0 auto;
 max-width:1100px;padding:1em 1.5em;color:#222;line-height:1.4}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;margin-top:1.8em}
h3{margin-top:1.3em}
table{border-collapse:collapse;margin:.6em 0;font-size:.85em}
th,td{border:1px solid #ccc;padding:.2em .45em;text-align:left;vertical-align:top}
th{background:#f0f0f0}td.n,th.n{text-align:right;white-space:nowrap}td.c{text-align:center}
div.scroll{overflow-x:auto;max-width:100%}
table.facts td{text-align:left}table.facts td:first-child{font-weight:600;background:#f7f7f7}
table.facts thead{display:none}
caption{text-align:left;font-weight:600;padding:.2em 0}
tr.channel th{text-align:left;background:#e4ecf5}tr.warning td{text-align:left;color:#8a5a00;background:#fff8e6}
tr.total td{font-weight:600}tr.significant td{background:#eaf7ea}
td.flagged{font-weight:700}
tr.why td{color:#555;font-size:.92em;border-top:none}
table.effects th{text-align:right}table.effects th:nth-child(-n+4){text-align:left}
table.heat td,table.heat th{text-align:center}
.note{color:#555;font-style:italic;background:#f7f7f7;border-left:3px solid #bbb;padding:.4em .6em}
.message{background:#fffbe6;border:1px solid #e6d48a;padding:.6em .8em;margin:.6em 0}
.na{color:#777;font-style:italic}.yes{color:#137a13}
figure{margin:.6em 0}figcaption{font-size:.85em;color:#555}
svg.plot{max-width:100%;height:auto;display:block}
svg.plot *{stroke-linejoin:round;stroke-linecap:butt}
nav ul{columns:2;font-size:.9em}
footer{margin-top:2em;color:#777;font-size:.8em}
@media print{nav{display:none}}
"""

_SECTIONS = (
    ("run", "Run"),
    ("preprocessing", "Preprocessing"),
    ("segments", "Filter and smoother, per segment"),
    ("coefficients", "Aerodynamic coefficients"),
    ("comparison", "Measured vs model"),
    ("diagnosis", "Diagnosis"),
    ("versions", "Model versions"),
    ("audit", "Audit trail"),
)

_INTROS = {
    "run": "What was processed, from which file (its SHA-256 identifies the exact bytes), by which code, and when.",
    "preprocessing": "The raw telemetry is put on a uniform time grid; dropouts, NaNs, spikes and frozen values are "
                     "flagged; short gaps are interpolated, long ones are left empty and split the flight into "
                     "segments.",
    "segments": "Each segment is run through the 21-state extended Kalman filter and the Modified Bryson–Frazier "
                "smoother. The table checks the filter's consistency; the plot shows the smoothed pitch rate with "
                "its uncertainty.",
    "coefficients": "The flight estimates of the aerodynamic coefficients from the multiple linear regression, "
                    "next to the preflight database (seed Table 3 style).",
    "comparison": "How well the fitted model reproduces the flight-derived coefficients (seed Figs. 6, 9, 10 "
                  "style).",
    "diagnosis": "Where the model fails (time windows, regimes), whether the residual is white, and which "
                 "physical effect is most likely missing.",
    "versions": "The modelling loop: every model that was fitted, what changed, and how the error moved.",
    "audit": "Every stage execution is recorded in the append-only ledger.",
}


def _guard(fn: Callable[[], str], what: str) -> str:
    try:
        return fn()
    except Exception as exc:  # one broken section must not lose the rest of the report
        return _note(f"The {what} section could not be rendered: {type(exc).__name__}: {exc}")


def build_report(run_dir: str | Path, *, diagnosis=None, truth=None) -> str:
    """The HTML report of RUN_DIR as one self-contained document (str).

    diagnosis: an :class:`aerosid.diagnosis.Diagnosis` (full regime map and the
    diagnosed model's comparison plots), a ``diagnosis.json`` dict or its path;
    default: ``RUN_DIR/diagnosis.json`` when present, else the section says there
    is no diagnosis yet.
    truth: a ``truth.json`` dict (or its path) of a simulated flight: adds the
    true values and the error % to the coefficients table.
    Reads the run folder only; never writes.
    """
    import matplotlib  # noqa: F401  (fail early and clearly if the plotting library is missing)

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise FileNotFoundError(f"{run_dir}: no such run folder")
    run = _Run.load(run_dir)
    doc, diag, source = _diagnosis_inputs(run, diagnosis)
    truth_c = _truth_coefficients(truth)
    generated = datetime.now(timezone.utc).isoformat(timespec="seconds")
    bodies = {
        "preprocessing": lambda: _per_flight(run, _s_preprocessing),
        "segments": lambda: _per_flight(run, _s_segments),
        "coefficients": lambda: _s_coefficients(run, truth_c),
        "comparison": lambda: _s_comparison(run, diag),
        "diagnosis": lambda: _s_diagnosis(doc, diag, source, run),
        "versions": lambda: _s_versions(run),
        "audit": lambda: _s_audit(run),
    }
    rendered = {sid: _guard(fn, sid) for sid, fn in bodies.items()}
    rendered["run"] = _guard(lambda: _s_header(run, generated), "run")  # last: lists the files found unreadable
    parts = [f'<section id={_q(sid)}>\n<h2>{_e(title)}</h2>\n{_p(_INTROS[sid], "intro")}\n{rendered[sid]}\n'
             "</section>" for sid, title in _SECTIONS]
    title = f"aerosid report — flight {run.flight}"
    nav = "<nav><ul>" + "".join(f'<li><a href="#{sid}">{_e(t)}</a></li>' for sid, t in _SECTIONS) + "</ul></nav>"
    return "\n".join([
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title>",
        f"<style>{_CSS}</style>",
        "</head>",
        "<body>",
        f"<header><h1>{_e(title)}</h1>",
        _p(f"Aerodynamic coefficients by Estimation Before Modeling. Vehicle {run.vehicle}. Generated "
           f"{generated} from {run_dir}. SI units and radians unless a column says otherwise."),
        "</header>",
        nav,
        *parts,
        "<footer>" + _e("Self-contained: no scripts, no external files; plots are inline SVG. Produced by "
                        "aerosid.report.") + "</footer>",
        "</body>",
        "</html>",
        "",
    ])


def write_report(run_dir: str | Path, *, diagnosis=None, truth=None, path: str | Path | None = None) -> Path:
    """Build the report and write it atomically to RUN_DIR/report.html (or `path`); returns the path."""
    from aerosid.io import write_text_atomic

    text = build_report(run_dir, diagnosis=diagnosis, truth=truth)
    return write_text_atomic(text, Path(path) if path is not None else Path(run_dir) / REPORT_NAME)
