"""Matplotlib figures as inline SVG (text drawn as paths, no fonts, no external files)."""
from __future__ import annotations

import io
import math
import re

import numpy as np

from aerosid.report.html import _e, _q

_MAX_POINTS = 4000  # per plotted series; longer series are thinned (every k-th sample)
_RC = {"svg.fonttype": "path", "svg.hashsalt": "aerosid-report", "path.simplify": True,
       "font.size": 9, "axes.grid": True, "grid.alpha": 0.3}


# --------------------------------------------------------------------------- SVG plots
def _svg(fig, key: str, label: str) -> str:
    """The figure as an inline <svg> element: text as paths (no fonts), no metadata,
    no namespace URLs, ids prefixed with `key` so several plots share one page."""
    import matplotlib

    buf = io.StringIO()
    with matplotlib.rc_context(_RC):
        # no bbox_inches="tight": the constrained layout already fits the figure, and "tight"
        # drew every figure twice (the report stage of a 40 s flight 9.4 -> 5.2 s)
        fig.savefig(buf, format="svg")
    text = buf.getvalue()
    text = text[text.index("<svg"):]
    text = re.sub(r"<metadata>.*?</metadata>", "", text, flags=re.S)
    text = re.sub(r'<style type="text/css">.*?</style>', "", text, flags=re.S)
    text = re.sub(r'\s+xmlns(:\w+)?="[^"]*"', "", text)
    ids = set(re.findall(r'\bid="([^"]+)"', text))
    text = re.sub(r'(\bid="|href="#|url\(#)([^")]+)',
                  lambda m: m.group(1) + (f"{key}-{m.group(2)}" if m.group(2) in ids else m.group(2)), text)
    text = _LONG_DECIMAL.sub(lambda m: f"{float(m.group(0)):.5g}", text)
    text = text.replace("<svg", f'<svg class="plot" role="img" aria-label={_q(label)}', 1)
    return f'<figure>{text}<figcaption>{_e(label)}</figcaption></figure>'


#: A number with more than three decimals: matplotlib writes coordinates in points with six
#: (519.256612); five significant digits (519.26) are 0.01 pt on a page ~1000 pt wide, far
#: below a screen pixel, and keep the glyphs' small scale factors exact (0.075).  About a
#: quarter of the report's bytes.
_LONG_DECIMAL = re.compile(r"(?<![\w#.])-?\d+\.\d{4,}")


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




# --------------------------------------------------------------------------- residual and regime plots
_SCATTER_POINTS = 150  # context dots per scatter panel (the binned band carries the shape)
_BINS = 16
DEG = 180.0 / math.pi


def binned(x: np.ndarray, y: np.ndarray, nbins: int = _BINS):
    """(x median, y mean, y 10th, y 90th percentile) per quantile bin of x (equal counts)."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 2 * nbins or np.ptp(x) <= 0:
        return (np.array([]),) * 4
    edges = np.unique(np.quantile(x, np.linspace(0, 1, nbins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
    out = []
    for b in range(edges.size - 1):
        m = idx == b
        if m.sum() >= 3:
            yy = y[m]
            out.append((float(np.median(x[m])), float(yy.mean()), float(np.percentile(yy, 10)),
                        float(np.percentile(yy, 90))))
    if not out:
        return (np.array([]),) * 4
    return tuple(np.array(c) for c in zip(*out))


def scatter_panel(ax, x: np.ndarray, y: np.ndarray, *, xlabel: str, ylabel: str, line=None) -> None:
    """A few dots for context, the binned mean with its 10-90 % band, and `line`
    ((x, y) of the fitted term) when given."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if x.size:
        sel = np.unique(np.linspace(0, x.size - 1, min(_SCATTER_POINTS, x.size)).astype(int))
        ax.plot(x[sel], y[sel], ".", color="0.65", ms=2.0, rasterized=True)  # one small image, not 150 <use>
    cx, m, lo, hi = binned(x, y)
    if cx.size:
        ax.fill_between(cx, lo, hi, color="tab:blue", alpha=0.18, lw=0)
        ax.plot(cx, m, "-", color="tab:blue", lw=1.3)
    if line is not None:
        ax.plot(line[0], line[1], "-", color="tab:red", lw=1.0)
    ax.axhline(0.0, color="0.4", lw=0.5)
    # panels are narrow: q_hat's ticks (-0.0005 ... 0.0005) overlapped; small ranges get a
    # power-of-ten offset instead
    ax.locator_params(axis="x", nbins=4)
    ax.ticklabel_format(axis="x", style="sci", scilimits=(-2, 4))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)


def regime_figure(bins_by_var: dict, flag_ratio: float):
    """One panel per regime variable: each channel's residual RMS ratio per bin (a step
    over the bin's range; angles in degrees), with the flag threshold."""
    names = list(bins_by_var)
    ncols = min(4, max(1, len(names)))
    nrows = math.ceil(len(names) / ncols)
    fig, axes = _figure((2.6 * ncols, 2.3 * nrows), nrows=nrows, ncols=ncols)
    for ax, var in zip(axes, names):
        unit, per_channel = bins_by_var[var]
        k, shown_unit = (DEG, "deg") if unit == "rad" else ((1e-3, "kPa") if unit == "Pa" else (1.0, unit))
        for ch, bins in per_channel.items():
            bins = sorted(bins, key=lambda b: b["lo"])
            edges = np.array([bins[0]["lo"]] + [b["hi"] for b in bins], float) * k
            ratios = np.array([b["rms_ratio"] if b["rms_ratio"] is not None else np.nan for b in bins], float)
            if np.all(np.diff(edges) > 0):
                ax.stairs(ratios, edges, label=ch, lw=1.2)
            else:  # touching or repeated quantiles: one point per bin
                ax.plot(0.5 * (edges[:-1] + edges[1:]), ratios, "o-", ms=3, label=ch)
        ax.axhline(flag_ratio, color="tab:red", lw=0.7, ls="--")
        ax.axhline(1.0, color="0.4", lw=0.5)
        ax.set_xlabel(f"{var} [{shown_unit}]")
        ax.set_ylabel("RMS ratio")
    for ax in axes[len(names):]:
        ax.set_visible(False)
    if names:
        axes[0].legend(fontsize=7, loc="best")
    return fig
