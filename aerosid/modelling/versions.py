"""Model versions of a run: every fit is kept, with its spec, metrics and parent.

Layout under ``RUN_DIR/models/``::

    v001/spec.toml            the model specification (aerosid.modelling.models TOML)
    v001/metrics.json         per channel: residual RMS, R^2, PSE, F, coefficients with sigma
    v001/coefficients.parquet the coefficients table (as RUN_DIR/coefficients.parquet)
    v001/parent               id of the parent version (empty for the root)

``v001`` is always the default models of method.md §11 (created on the first
fit).  A version is immutable: the next id is claimed with ``os.mkdir`` (atomic;
two concurrent fits get different ids), its files are written atomically, and
``metrics.json`` is written last, so a directory without it is an unfinished or
crashed fit and is ignored (and removed by the fit that failed, when it can).
"""
from __future__ import annotations

import json
import math
import os
import re
import shutil
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd

from aerosid.identification.identify import identify
from aerosid.io import write_json_atomic, write_parquet_atomic, write_text_atomic
from aerosid.modelling.models import CHANNELS, ChannelModel, ModelSpecError, default_models, load_models, models_to_toml

__all__ = ["ModelVersion", "VersionHistory", "fit_version", "history", "load_version", "latest_models",
           "read_flight_data", "run_vehicle", "models_from_spec", "spec_for_run", "MODELS_DIR", "VersionError"]

MODELS_DIR = "models"
#: held-out errors within this fraction of each other are reported as a tie in `history`
HELDOUT_TIE = 0.01
_ID = re.compile(r"^v(\d{3,})$")


class VersionError(ValueError):
    """A run directory or version that cannot be used; the message names the file."""


@dataclass(frozen=True)
class ModelVersion:
    """One fitted model version (read back from disk)."""

    id: str
    parent: str | None
    note: str
    created_utc: str
    models: dict = field(repr=False)  # channel -> ChannelModel
    metrics: dict = field(repr=False)  # the metrics.json document
    path: Path = field(repr=False)

    @property
    def number(self) -> int:
        return int(self.id[1:])

    def channel_metric(self, channel: str, key: str) -> float:
        v = self.metrics["channels"].get(channel, {}).get(key)
        return float("nan") if v is None else float(v)

    def coefficients(self) -> pd.DataFrame:
        rows = []
        for ch, m in self.metrics["channels"].items():
            for name, c in m["coefficients"].items():
                rows.append({"channel": ch, "coefficient": name, **c})
        return pd.DataFrame(rows)

    def summary(self) -> str:
        lines = [f"model version {self.id} (parent {self.parent or '-'}){': ' + self.note if self.note else ''}",
                 f"  fitted {self.created_utc} on {self.metrics.get('n_samples')} samples, vehicle "
                 f"{self.metrics.get('vehicle')}",
                 f"  {'channel':<8}{'RMS':>11}{'R^2':>11}{'PSE':>11}{'F (OLS)':>12}{'F corr':>10}  terms"]
        for ch, m in self.metrics["channels"].items():
            lines.append(f"  {ch:<8}{_fmt(m['rms_residual'], '.4g'):>11}{_fmt(m['r2'], '.6f'):>11}"
                         f"{_fmt(m['pse'], '.4g'):>11}{_fmt(m['f_stat'], '.4g'):>12}{_fmt(m['f_stat_corrected'], '.4g'):>10}"
                         f"  {', '.join(m['terms'])}")
        return "\n".join(lines)


def _fmt(x, spec: str) -> str:
    return "nan" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


@dataclass(frozen=True)
class VersionHistory:
    """All complete versions of a run, oldest first."""

    run_dir: Path
    versions: tuple[ModelVersion, ...]

    def __len__(self) -> int:
        return len(self.versions)

    @property
    def latest(self) -> ModelVersion | None:
        return self.versions[-1] if self.versions else None

    def get(self, version_id: str) -> ModelVersion:
        for v in self.versions:
            if v.id == version_id:
                return v
        raise VersionError(f"{self.run_dir / MODELS_DIR}: no version {version_id!r} "
                           f"(have: {', '.join(v.id for v in self.versions) or 'none'})")

    def changes(self, v: ModelVersion) -> str:
        """Terms added/removed relative to the parent ('default' for a root with the default models)."""
        if v.parent is None:
            return ("default models" if _same_models(v.models, run_default_models(self.run_dir))
                    else "root: " + _spec_brief(v.models))
        try:
            p = self.get(v.parent)
        except VersionError:
            return f"(parent {v.parent} missing) " + _spec_brief(v.models)
        return _diff(p.models, v.models) or "no change"

    def heldout(self, v: ModelVersion, channel: str) -> float:
        """Leave-one-window-out prediction RMS (metrics.json `heldout_rms`; computed from the
        run's flight data for versions fitted before it was stored, not written back)."""
        x = v.channel_metric(channel, "heldout_rms")
        if math.isfinite(x):
            return x
        return _heldout_backfill(self.run_dir, v).get(channel, float("nan"))

    def heldout_ranks(self) -> dict[str, int]:
        """Version -> rank (1 = best) by held-out prediction error: the mean over channels of
        each channel's held-out RMS relative to the best version's in that channel."""
        if not self.versions:
            return {}
        chans = list(self.versions[0].metrics["channels"])
        h = {v.id: {ch: self.heldout(v, ch) for ch in chans} for v in self.versions}
        best = {ch: min((h[v][ch] for v in h if math.isfinite(h[v][ch])), default=float("nan")) for ch in chans}
        score = {}
        for vid, d in h.items():
            r = [d[ch] / best[ch] for ch in chans if math.isfinite(d[ch]) and math.isfinite(best[ch]) and best[ch] > 0]
            score[vid] = sum(r) / len(r) if r else float("inf")
        order = sorted(score, key=lambda k: score[k])
        return {vid: i + 1 for i, vid in enumerate(order)}

    def table(self) -> pd.DataFrame:
        rows = []
        ranks = self.heldout_ranks()
        for v in self.versions:
            row = {"version": v.id, "parent": v.parent or "", "changes": self.changes(v), "note": v.note,
                   "rank_heldout": ranks.get(v.id)}
            for ch in v.metrics["channels"]:
                for key, label in (("rms_residual", "rms"), ("r2", "r2"), ("pse", "pse")):
                    row[f"{label}_{ch}"] = v.channel_metric(ch, key)
                row[f"heldout_{ch}"] = self.heldout(v, ch)
            rows.append(row)
        return pd.DataFrame(rows)

    def plot_data(self) -> pd.DataFrame:
        """Long format for a plot of error against version: version, number, channel, rms, r2, pse."""
        rows = [{"version": v.id, "number": v.number, "channel": ch, "rms": v.channel_metric(ch, "rms_residual"),
                 "r2": v.channel_metric(ch, "r2"), "pse": v.channel_metric(ch, "pse")}
                for v in self.versions for ch in v.metrics["channels"]]
        return pd.DataFrame(rows)

    def figure(self, channels: tuple[str, ...] | None = None):
        """Residual RMS of each channel against version (matplotlib Figure)."""
        import matplotlib.pyplot as plt

        data = self.plot_data()
        fig, ax = plt.subplots(figsize=(7, 4))
        for ch, g in data.groupby("channel", sort=False):
            if channels and ch not in channels:
                continue
            ax.plot(g["number"], g["rms"], "o-", label=ch)
        ax.set_yscale("log")
        ax.set_xlabel("model version")
        ax.set_ylabel("residual RMS")
        ax.legend()
        return fig

    def summary(self) -> str:
        if not self.versions:
            return (f"{self.run_dir}: no model versions yet; `aerosid fit {self.run_dir}` creates v001 "
                    "(the default models)")
        lines = [f"model versions of {self.run_dir}, ranked by held-out prediction error (leave-one-window-out "
                 "RMS: each time block predicted by a fit made without it; in-sample residual RMS in brackets; "
                 "lower is better; * = best held-out in the channel)"]
        chans = list(self.versions[0].metrics["channels"])
        ranks = self.heldout_ranks()
        held = {v.id: {ch: self.heldout(v, ch) for ch in chans} for v in self.versions}
        best = {ch: min((held[v][ch] for v in held if math.isfinite(held[v][ch])), default=None) for ch in chans}
        head = f"  {'rank':<5}{'version':<8}{'parent':<8}" + "".join(f"{ch:>22}" for ch in chans) + "  changes"
        lines.append(head)
        for v in sorted(self.versions, key=lambda x: ranks.get(x.id, 10 ** 6)):
            cells = "".join(f"{_fmt(held[v.id][ch], '.4g') + ('*' if held[v.id][ch] == best[ch] else ' '):>12}"
                            f"{'(' + _fmt(v.channel_metric(ch, 'rms_residual'), '.4g') + ')':>10}" for ch in chans)
            note = f" ({v.note})" if v.note else ""
            lines.append(f"  {ranks.get(v.id, '-'):<5}{v.id:<8}{(v.parent or '-'):<8}{cells}  {self.changes(v)}{note}")
        for ch in chans:  # near ties between different models of a channel are not a ranking
            vals = sorted(((held[v.id][ch], v) for v in self.versions if math.isfinite(held[v.id][ch])),
                          key=lambda hv: hv[0])
            if len(vals) >= 2 and vals[1][0] - vals[0][0] < HELDOUT_TIE * vals[0][0] \
                    and vals[0][1].models[ch].terms != vals[1][1].models[ch].terms:
                lines.append(f"  note: {ch}: {vals[0][1].id} and {vals[1][1].id} predict within "
                             f"{100 * (vals[1][0] / vals[0][0] - 1):.1f} % of each other (< {HELDOUT_TIE:.0%}): "
                             "not a meaningful difference; `aerosid diagnose` compares look-alike terms directly")
        return "\n".join(lines)


_HELDOUT_CACHE: dict = {}


def _heldout_backfill(run_dir: Path, v: ModelVersion) -> dict:
    """Held-out RMS of a version whose metrics.json predates it (read-only, cached)."""
    key = (str(Path(run_dir).resolve()), v.id, (v.path / "metrics.json").stat().st_mtime_ns)
    if key not in _HELDOUT_CACHE:
        try:
            from aerosid.diagnosis.heldout import heldout_rms
            from aerosid.vehicles.vehicle import load_vehicle

            _HELDOUT_CACHE[key] = heldout_rms(read_flight_data(run_dir), load_vehicle(run_vehicle(run_dir)), v.models,
                                              v.metrics.get("mach_half_width", 0.5))
        except (VersionError, ValueError, OSError):
            _HELDOUT_CACHE[key] = {}
    return _HELDOUT_CACHE[key]


def _same_models(a: dict, b: dict) -> bool:
    return {k: m.terms for k, m in a.items()} == {k: m.terms for k, m in b.items()}


def _term_label(t) -> str:
    return t.effect or f"{t.coefficient} = {t.expression}"


def _spec_brief(models: dict) -> str:
    return "; ".join(f"{ch}: {', '.join(t.coefficient for t in m.terms)}" for ch, m in models.items())


def _diff(old: dict, new: dict) -> str:
    parts = []
    for ch in new:
        o = {t.coefficient: t for t in old[ch].terms} if ch in old else {}
        n = {t.coefficient: t for t in new[ch].terms}
        added = [_term_label(n[k]) for k in n if k not in o or o[k] != n[k]]
        removed = [k for k in o if k not in n]
        if added or removed:
            parts.append(f"{ch}: " + ", ".join([f"+{a}" for a in added] + [f"-{r}" for r in removed]))
    for ch in old:
        if ch not in new:
            parts.append(f"-[{ch}]")
    return "; ".join(parts)


# --------------------------------------------------------------------------- run directory
def read_flight_data(run_dir: str | Path) -> pd.DataFrame:
    path = Path(run_dir) / "flight_data.parquet"
    if not path.is_file():
        raise VersionError(f"{path}: no flight data (run `aerosid run TELEMETRY --out {run_dir}` first)")
    try:
        return pd.read_parquet(path)
    except Exception as exc:  # pyarrow raises several types
        raise VersionError(f"{path}: cannot read the flight data ({exc})") from exc


def run_vehicle(run_dir: str | Path) -> str:
    """The vehicle name or file recorded in RUN_DIR/run.json, else 'seed-rlv'."""
    path = Path(run_dir) / "run.json"
    if path.is_file():
        try:
            doc = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise VersionError(f"{path}: not valid JSON ({exc})") from exc
        if isinstance(doc, dict) and doc.get("vehicle"):
            return str(doc["vehicle"])
    return "seed-rlv"


def run_default_models(run_dir: str | Path) -> dict[str, ChannelModel]:
    """The default models of the run's vehicle (its [models] table, else method.md §11)."""
    from aerosid.vehicles.vehicle import load_vehicle

    # a run whose vehicle file cannot be read fails here, naming the file: falling back to
    # another vehicle's models would fit the wrong terms under the name "default models"
    return default_models(load_vehicle(run_vehicle(run_dir)))


def load_version(path: str | Path) -> ModelVersion:
    path = Path(path)
    metrics_path = path / "metrics.json"
    try:
        metrics = json.loads(metrics_path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise VersionError(f"{metrics_path}: cannot read the version metrics ({exc})") from exc
    parent_text = (path / "parent").read_text().strip() if (path / "parent").is_file() else ""
    models = load_models(path / "spec.toml", base={})
    return ModelVersion(path.name, parent_text or None, metrics.get("note", ""), metrics.get("created_utc", ""),
                        models, metrics, path)


def history(run_dir: str | Path) -> VersionHistory:
    """The complete versions under RUN_DIR/models (read only; creates nothing)."""
    root = Path(run_dir) / MODELS_DIR
    versions = []
    if root.is_dir():
        for p in sorted(root.iterdir(), key=lambda q: (len(q.name), q.name)):
            if p.is_dir() and _ID.match(p.name) and (p / "metrics.json").is_file():
                versions.append(load_version(p))
    return VersionHistory(Path(run_dir), tuple(versions))


def latest_models(run_dir: str | Path) -> dict[str, ChannelModel]:
    """The models of the latest version, or the defaults when there is none."""
    h = history(run_dir)
    return dict(h.latest.models) if h.latest else run_default_models(run_dir)


def _claim(root: Path) -> Path:
    """Create the next vNNN directory atomically (os.mkdir fails if it exists)."""
    root.mkdir(parents=True, exist_ok=True)
    nums = [int(m.group(1)) for p in root.iterdir() if (m := _ID.match(p.name))]
    k = max(nums, default=0) + 1
    while True:
        path = root / f"v{k:03d}"
        try:
            os.mkdir(path)
            return path
        except FileExistsError:
            k += 1


def _metrics(ident, vehicle: str, note: str, parent: str | None, version: str, mach_half_width,
             heldout: dict | None = None) -> dict:
    def f(x):
        x = float(x)
        return x if math.isfinite(x) else None

    chans = {}
    crb = getattr(ident, "crb_std", {}) or {}
    identities = tuple(getattr(ident, "identities", ()))
    for ch, fit in ident.fits.items():
        chans[ch] = {
            "terms": [_term_label(t) for t in ident.models[ch].terms],
            "rms_residual": f(fit.rms_residual), "heldout_rms": f((heldout or {}).get(ch, float("nan"))),
            "r2": f(fit.r2), "pse": f(fit.pse), "f_stat": f(fit.f_stat),
            "f_stat_corrected": f(fit.f_stat_corrected), "n_eff": f(fit.n_eff), "n_obs": int(fit.n_obs),
            "coefficients": {n: {"estimate": f(fit.estimate[i]), "std_error": f(fit.std_error[i]),
                                 "std_error_ols": f(fit.std_error_ols[i]),
                                 # the Cramer-Rao bound on the std (aerosid.identification.crb), as in
                                 # coefficients.parquet: how far the reported sigma is from the best possible
                                 "crb_std": f(crb.get(n, float("nan")))} for i, n in enumerate(fit.names)},
            # alpha/beta inverted from this channel: its fit returns the preflight database by construction
            "identity": ch in identities,
            "warnings": list(fit.warnings),
        }
    return {"version": version, "parent": parent, "note": note,
            "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"), "vehicle": vehicle,
            # +/- pairs of the estimator-bias check in the sigma (aerosid.identification.bias_check; 0: none)
            "bias_check_pairs": int(getattr(ident, "bias_pairs", 0)),
            "n_samples": int(ident.n_samples), "mach_window": list(ident.mach_window),
            "mach_half_width": mach_half_width, "channels": chans}


def _write_version(run_dir: Path, fd: pd.DataFrame, vehicle_name: str, models: dict, parent: str | None, note: str,
                   mach_half_width) -> ModelVersion:
    from aerosid.vehicles.vehicle import load_vehicle

    veh = load_vehicle(vehicle_name)
    ident = identify(fd, veh, models, mach_half_width)  # fit before claiming an id: a failed fit leaves nothing
    from aerosid.diagnosis.heldout import heldout_rms

    heldout = heldout_rms(fd, veh, models, mach_half_width)
    path = _claim(run_dir / MODELS_DIR)
    try:
        write_text_atomic(models_to_toml(models), path / "spec.toml")
        write_parquet_atomic(ident.table(), path / "coefficients.parquet", metadata={"aerosid.kind": "coefficients",
                                                                                    "aerosid.model_version": path.name})
        write_text_atomic((parent or "") + "\n", path / "parent")
        write_json_atomic(_metrics(ident, vehicle_name, note, parent, path.name, mach_half_width, heldout),
                          path / "metrics.json")
    except BaseException:
        shutil.rmtree(path, ignore_errors=True)
        raise
    return load_version(path)


def fit_version(run_dir: str | Path, models: dict[str, ChannelModel] | None = None, parent: str | None = None,
                note: str = "", *, mach_half_width: float | None = 0.5) -> ModelVersion:
    """Fit `models` to RUN_DIR/flight_data.parquet and store the result as a new version.

    The first fit of a run also stores v001 = the default models (the root);
    `parent` defaults to the latest version.  Returns the new version (v001 itself
    when `models` is None or equal to the defaults and no version exists yet).
    """
    run_dir = Path(run_dir)
    fd = read_flight_data(run_dir)
    vehicle_name = run_vehicle(run_dir)
    defaults = run_default_models(run_dir)
    models = dict(models) if models is not None else defaults
    unknown = set(models) - set(CHANNELS)
    if unknown:
        raise ModelSpecError(f"unknown channel(s) {sorted(unknown)}; channels: {', '.join(CHANNELS)}")
    h = history(run_dir)
    if not h.versions:
        root = _write_version(run_dir, fd, vehicle_name, defaults, None, "default models", mach_half_width)
        if _same_models(models, defaults) and parent is None:
            return root
        h = history(run_dir)
    if parent is None:
        parent = h.latest.id
    else:
        h.get(parent)  # raises with the list of versions if unknown
    return _write_version(run_dir, fd, vehicle_name, models, parent, note, mach_half_width)


def models_from_spec(spec: str | Path, run_dir: str | Path, parent: str | None = None) -> dict[str, ChannelModel]:
    """Read a spec file; channels it does not mention keep the parent version's terms
    (the latest version's, or the defaults when there is none)."""
    return spec_for_run(spec, run_dir, parent).models


def spec_for_run(spec: str | Path, run_dir: str | Path, parent: str | None = None):
    """A spec file applied to the run's parent version (`parent`, else the latest, else the
    defaults): an aerosid.modelling.model_specs.SpecResult (the models and what changed, with a
    warning for every term a ``terms = [...]`` replacement dropped)."""
    from aerosid.modelling.model_specs import read_spec
    from aerosid.vehicles.vehicle import load_vehicle

    h = history(run_dir)
    base = h.get(parent).models if parent else (h.latest.models if h.latest else run_default_models(run_dir))
    return read_spec(spec, dict(base), load_vehicle(run_vehicle(run_dir)).mach_reference)
