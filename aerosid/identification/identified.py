"""The identified model of a run folder: each channel's terms and their estimates.

A run folder (``aerosid run``) holds ``coefficients.parquet`` (one row per channel
and coefficient, with the term's ``expression``) and, once ``aerosid fit`` has been
used, model versions under ``models/vNNN/`` (``spec.toml`` and the version's own
``coefficients.parquet``).  The model used is the latest version when there is one,
else the run's own coefficients.  Coefficients are SI per radian (per radian of
delta/2 for the finned class's pitch/yaw fin terms), moments about the CG.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.modelling.expressions import compile_expression, names_in
from aerosid.modelling.models import CHANNELS, SIGNALS, ChannelModel, Term

_SIGNALS = frozenset(SIGNALS)


class ModelSourceError(ValueError):
    """The run folder holds no usable identified model; the message names the file."""


@dataclass(frozen=True)
class IdentifiedModel:
    """Channel models with one value per coefficient.

    models: channel -> ChannelModel; values: coefficient -> estimate (NaN: not
    identifiable in the run); source: where it was read (for reports)."""

    models: dict
    values: dict
    source: str = "<memory>"
    vehicle: str = ""
    mach_half_width: float | None = 0.5
    path: str = field(default="", compare=False)  # the coefficients.parquet its values were read from ("": none)
    #: coefficients whose values are the preflight database's, not estimates (with_preflight_identities):
    #: a simulation reads them, a refinement leaves them fixed; the table at ``path`` keeps them NaN
    preflight: tuple = field(default=(), compare=False)
    _compiled: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        for ch, m in self.models.items():
            for t in m.terms:
                if t.coefficient not in self.values:
                    raise ModelSourceError(f"{self.source}: [{ch}] term {t.coefficient} has no value")
                self._compiled[(ch, t.coefficient)] = compile_expression(t.expression, _SIGNALS)

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.models)

    def unidentified(self, channels=None) -> list[str]:
        """Coefficients of these channels without a finite value."""
        chans = self.channels if channels is None else [c for c in channels if c in self.models]
        return [t.coefficient for ch in chans for t in self.models[ch].terms
                if not math.isfinite(float(self.values[t.coefficient]))]

    def reads(self, channel: str) -> frozenset[str]:
        """The signal names a channel's model reads."""
        if channel not in self.models:
            return frozenset()
        return frozenset().union(*(names_in(t.expression, _SIGNALS) for t in self.models[channel].terms))

    def intercepts(self, channel: str) -> list[str]:
        """The channel's constant terms (e.g. Cm_0 = 1)."""
        if channel not in self.models:
            return []
        return [t.coefficient for t in self.models[channel].terms if not names_in(t.expression, _SIGNALS)]

    def weighted_terms(self, channel: str, values: dict | None = None) -> list:
        """[(term's compiled function of the signals, value), ...] of the channel's terms that
        count, in order: a NaN (unidentified) or zero value adds nothing.  For a loop that
        evaluates the same channel many times (a simulation): look them up once."""
        vals = self.values if not values else {**self.values, **values}
        out = []
        for t in self.models[channel].terms:
            v = float(vals[t.coefficient])
            if math.isfinite(v) and v != 0.0:
                out.append((self._compiled[(channel, t.coefficient)], v))
        return out

    def evaluate(self, channel: str, signals: dict, values: dict | None = None) -> np.ndarray:
        """The channel's coefficient sum_j value_j * term_j(signals); `values` overrides some
        coefficients.  Unidentified coefficients count as 0 (the caller warns)."""
        return np.asarray(weighted_sum(self.weighted_terms(channel, values), signals), dtype=float)

    def with_values(self, **values: float) -> "IdentifiedModel":
        unknown = set(values) - set(self.values)
        if unknown:
            raise KeyError(f"unknown coefficient(s) {sorted(unknown)}; the model has {sorted(self.values)}")
        return replace(self, values={**self.values, **values}, path="", _compiled={})

    def table(self) -> pd.DataFrame:
        return pd.DataFrame([{"channel": ch, "coefficient": t.coefficient, "expression": t.expression,
                              "estimate": float(self.values[t.coefficient])}
                             for ch, m in self.models.items() for t in m.terms])

    def summary(self) -> str:
        lines = [f"identified model from {self.source} (vehicle {self.vehicle or '?'})"]
        for ch, m in self.models.items():
            terms = " + ".join(f"{self.values[t.coefficient]:.5g}*({t.expression})" for t in m.terms)
            lines.append(f"  {ch} = {terms}")
        return "\n".join(lines)


def weighted_sum(terms, signals):
    """sum of value * term(signals) over IdentifiedModel.weighted_terms' pairs, in their order
    (0.0 for none)."""
    total = 0.0
    for fn, v in terms:
        total = total + v * fn(signals)
    return total


def with_preflight_identities(model: IdentifiedModel, vehicle) -> tuple[IdentifiedModel, list[str]]:
    """The model to simulate, and a note: the unidentified coefficients of the channels that are
    identities by construction (C_N and C_Y when alpha and beta are inverted from them through the
    preflight force database, aerosid.identification.identify.identity_channels) take the preflight
    database's linear values about the CG.  The inversion made the flight's C_N and C_Y equal to that
    database, so it is the model of those channels; as 0 they would leave the simulated alpha
    without its lift and a_z without its force.  Listed in ``preflight``; ``path`` is kept (the
    table there still says "not identifiable")."""
    from aerosid.identification.identify import identity_channels
    from aerosid.modelling.aeromodel import AeroModel

    chans = identity_channels(vehicle, model.models)
    missing = model.unidentified(chans)
    if not missing or getattr(vehicle, "preflight", None) is None:
        return model, []
    refs = AeroModel.preflight(vehicle).linear_truth()
    vals = {k: float(refs[k]) for k in missing if k in refs and math.isfinite(float(refs[k]))}
    if not vals:
        return model, []
    note = (f"{'/'.join(chans)}: identities by construction (alpha, beta are inverted from them through the "
            "preflight force database), so the simulation uses that database's values: "
            + ", ".join(f"{k} {v:.4g}" for k, v in vals.items()))
    return replace(model, values={**model.values, **vals}, preflight=tuple(vals), _compiled={}), [note]


def model_from_table(table: pd.DataFrame, source: str, vehicle: str = "",
                     mach_half_width: float | None = 0.5, path: str | Path = "") -> IdentifiedModel:
    """An IdentifiedModel from coefficients.parquet rows (channel, coefficient, expression, estimate)."""
    need = {"channel", "coefficient", "expression", "estimate"}
    missing = sorted(need - set(table.columns))
    if missing:
        raise ModelSourceError(f"{source}: no column(s) {missing}: cannot rebuild the model's terms "
                               "(written by an older aerosid? re-run `aerosid fit`)")
    models, values = {}, {}
    for ch, rows in table.groupby("channel", sort=False):
        if ch not in CHANNELS:
            raise ModelSourceError(f"{source}: unknown channel {ch!r}")
        terms = []
        for _, r in rows.iterrows():
            expr = str(r["expression"]).strip()
            if not expr:
                raise ModelSourceError(f"{source}: [{ch}] {r['coefficient']} has an empty expression")
            terms.append(Term(str(r["coefficient"]), expr))
            values[str(r["coefficient"])] = float(r["estimate"]) if pd.notna(r["estimate"]) else float("nan")
        models[str(ch)] = ChannelModel(str(ch), tuple(terms))
    if not models:
        raise ModelSourceError(f"{source}: no coefficients")
    return IdentifiedModel(models, values, source, vehicle, mach_half_width, str(path))


def read_run_json(run_dir: str | Path) -> dict:
    path = Path(run_dir) / "run.json"
    if not path.is_file():
        return {}
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ModelSourceError(f"{path}: not valid JSON ({exc})") from exc
    return doc if isinstance(doc, dict) else {}


def load_model_file(path: str | Path, run_dir: str | Path) -> IdentifiedModel:
    """The model of a coefficients table outside the run's versions (e.g. ``aerosid refine``'s
    coefficients.parquet), for the run's vehicle and Mach window."""
    import pyarrow.parquet as pq

    from aerosid.modelling.versions import VersionError, run_vehicle

    path = Path(path)
    table = _read_coefficients(path)
    try:
        vehicle = run_vehicle(run_dir)
        meta = pq.read_schema(path).metadata or {}
    except VersionError as exc:
        raise ModelSourceError(str(exc)) from exc
    # the Mach window the table was identified (or refined) in, else the run's
    job = read_run_json(run_dir).get("job") or {}
    mhw = meta.get(b"aerosid.mach_half_width")
    try:
        mhw = (None if mhw.decode() == "none" else float(mhw)) if mhw is not None else job.get("mach_half_width", 0.5)
    except ValueError as exc:
        raise ModelSourceError(f"{path}: its aerosid.mach_half_width metadata {mhw!r} is not a number") from exc
    return model_from_table(table, str(path), vehicle, mhw, path)


def _read_coefficients(path: Path) -> pd.DataFrame:
    try:
        return pd.read_parquet(path)
    except Exception as exc:  # pyarrow raises several types
        raise ModelSourceError(f"{path}: cannot read the coefficients ({exc})") from exc


def load_identified_model(run_dir: str | Path, version: str | None = None) -> IdentifiedModel:
    """The run's identified model: `version` (vNNN), else the latest model version, else
    RUN_DIR/coefficients.parquet."""
    from aerosid.modelling.versions import VersionError, history, run_vehicle

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ModelSourceError(f"{run_dir}: no such run folder (make one with `aerosid run TELEMETRY --out {run_dir}`)")
    job = read_run_json(run_dir).get("job") or {}
    try:
        vehicle = run_vehicle(run_dir)
        h = history(run_dir)
        v = h.get(version) if version else h.latest
    except VersionError as exc:
        raise ModelSourceError(str(exc)) from exc
    if v is not None:
        path = v.path / "coefficients.parquet"
        source = f"{run_dir}/models/{v.id}"
        mhw = v.metrics.get("mach_half_width", job.get("mach_half_width", 0.5))
    else:
        path = run_dir / "coefficients.parquet"
        source = str(path)
        mhw = job.get("mach_half_width", 0.5)
    if not path.is_file():
        raise ModelSourceError(f"{path}: no coefficients (run `aerosid run TELEMETRY --out {run_dir}` first)")
    table = _read_coefficients(path)
    model = model_from_table(table, source, vehicle, mhw, path)
    if v is not None:  # the version's spec is the authority on its terms
        spec = {ch: m.terms for ch, m in v.models.items()}
        if {ch: tuple(t.coefficient for t in ts) for ch, ts in spec.items()} != \
                {ch: m.names for ch, m in model.models.items()}:
            raise ModelSourceError(f"{path}: its coefficients do not match {v.path / 'spec.toml'}")
    return model
