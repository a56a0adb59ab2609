"""Reading a run folder for the report: run.json, the ledger, Parquet files and their
metadata, the diagnosis and truth inputs, the pooled manoeuvres of a pooled run."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import pandas as pd

from aerosid.report.html import _e, _finite, _q


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
        inside = Path(diagnosis).resolve().parent == run.dir.resolve()
        return doc, None, Path(diagnosis).name if inside else str(diagnosis)
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




# --------------------------------------------------------------------------- the model shown
#: coefficients.parquet's note on a channel that is an identity by construction (aerosid.identification.identify)
IDENTITY_PREFIX = "not identifiable from this telemetry"


@dataclass(frozen=True)
class Shown:
    """The model the report shows everywhere (coefficients, comparison, residual plots):
    a stored version (the latest, or the one asked for), or RUN_DIR/coefficients.parquet
    when the run has no versions yet."""

    version: str | None
    latest: str | None
    table: pd.DataFrame | None = field(repr=False)
    table_name: str
    mach_half_width: float | None
    history: object | None = field(repr=False)  # aerosid.modelling.versions.VersionHistory
    problem: str | None = None  # the version history could not be read

    @property
    def label(self) -> str:
        if self.version is None:
            return "coefficients.parquet (no model versions yet)"
        if self.version == self.latest:
            return f"model version {self.version} (the latest)"
        return f"model version {self.version} (chosen; the latest is {self.latest})"

    @property
    def identities(self) -> tuple[str, ...]:
        """Channels the table reports as identities by construction (alpha, beta inverted
        from them): no estimate, note 'not identifiable from this telemetry ...'."""
        t = self.table
        if t is None or t.empty or "note" not in t.columns:
            return ()
        out = []
        for ch, g in t.groupby("channel", sort=False):
            notes = g["note"].fillna("").astype(str)
            if len(g) and notes.str.startswith(IDENTITY_PREFIX).all():
                out.append(str(ch))
        return tuple(out)


def shown_model(run: _Run, version: str | None = None) -> Shown:
    """The version to show: `version`, else the latest; without versions the run's
    coefficients.parquet.  An unknown `version` raises VersionError (it names the ones there are)."""
    from aerosid.modelling.versions import history

    job_half = (run.run.get("job") or {}).get("mach_half_width", 0.5)
    try:
        h = history(run.dir)
    except Exception as exc:  # a corrupt version must not lose the report (unless one was asked for)
        if version is not None:
            raise
        name = "coefficients.parquet"
        return Shown(None, None, run.frame(name), name, job_half, None,
                     f"the model versions could not be read: {type(exc).__name__}: {exc}")
    v = h.get(version) if version is not None else h.latest
    if v is None:
        name = "coefficients.parquet"
        return Shown(None, None, run.frame(name), name, job_half, h)
    name = f"models/{v.id}/coefficients.parquet"
    half = v.metrics["mach_half_width"] if "mach_half_width" in v.metrics else 0.5
    return Shown(v.id, h.latest.id, run.frame(name), name, half, h)


def diagnosis_terms(doc: dict | None, diag) -> dict[str, tuple[str, ...]]:
    """Channel -> the coefficient names of the diagnosed model."""
    if diag is not None and getattr(diag, "models", None):
        return {ch: tuple(m.names) for ch, m in diag.models.items()}
    chans = (doc or {}).get("channels") or {}
    return {ch: tuple(c.get("terms") or ()) for ch, c in chans.items() if isinstance(c, dict)}


def diagnosed_model(doc: dict | None, diag, shown: Shown) -> str | None:
    """Which model the diagnosis is of: diagnosis.json's ``model`` when recorded, else the
    newest stored version with the same terms in every channel (None when none matches)."""
    if doc and doc.get("model"):
        return str(doc["model"])
    terms = diagnosis_terms(doc, diag)
    h = shown.history
    if not terms or h is None:
        return None
    for v in reversed(h.versions):
        if {ch: tuple(m.names) for ch, m in v.models.items()} == terms:
            return v.id
    return None
