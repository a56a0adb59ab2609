"""Import a flight-test CSV with a map file naming each raw column's source and unit.

The map (TOML)::

    vehicle = "vehicle.toml"      # a vehicle file to copy (relative to the map) or a built-in name;
                                  # or, instead, a [vehicle] table in the vehicle-file layout
    [csv]                         # optional reading options
    delimiter = ","
    comment = "#"                 # lines starting with it are skipped
    decimal = "."                 # "," for a decimal comma (then the delimiter is usually ";")
    time_from_zero = false        # true: subtract the first time stamp

    [columns]                     # raw column = { column = CSV header, unit = its unit [, sign = -1] }
    t_s = { column = "time", unit = "s" }
    q_rad_s = { column = "q", unit = "deg/s" }
    V_m_s = { column = "KCAS", unit = "kt", airspeed = "calibrated" }   # converted to the true airspeed
    ...

Every raw contract column (schemas/telemetry.py RAW_COLUMNS) must be mapped; the
vanes, measured air data and attitude columns (aerosid.vehicles.units.TARGET_UNITS)
may be.  Units are read by pint (``g`` is standard gravity); each conversion is
recorded in the Parquet metadata.  V_m_s's ``airspeed`` (aerosid.vehicles.airspeed.AIRSPEED_KINDS,
default "true") converts a calibrated, indicated or equivalent airspeed to the true one with
h_m (and the measured p_static_pa, T_total_K, rho_kg_m3 when mapped); a V_m_s whose CSV header reads as
one of those (KIAS, cas_kt, "calibrated airspeed") must state it.  An example:
aerosid/data/examples/twin-otter-018.map.toml.
"""
from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.vehicles.airspeed import AIRSPEED_KINDS
from aerosid.vehicles.importers import ImportDataError, ImportedFlight, check_time
from aerosid.vehicles.units import TARGET_UNITS, Conversion, UnitError, conversion

_ENTRY_KEYS = {"column", "unit", "sign", "airspeed", "pressure"}
#: CSV headers that read as an airspeed other than the true one (tokens, lower case) ...
_NOT_TRUE_AIRSPEED_TOKENS = {"ias", "kias", "cas", "kcas", "eas", "keas", "vias", "vcas", "veas", "vi", "vc", "ve",
                             "vind", "vcal", "veq"}
#: ... or that hold one of these words anywhere.
_NOT_TRUE_AIRSPEED_WORDS = ("indicated", "calibrated", "equivalent")
#: qbar_pa headers that read as an impact pressure q_c = p_t - p (tokens; words anywhere).
_IMPACT_PRESSURE_TOKENS = {"qc", "qci", "qcic", "ptps"}
_IMPACT_PRESSURE_WORDS = ("impact",)
#: What a qbar_pa column may hold (an import map's ``pressure`` key).
PRESSURE_KINDS = ("dynamic", "impact")
_CSV_KEYS = {"delimiter", "comment", "decimal", "time_from_zero"}


@dataclass(frozen=True)
class ColumnMap:
    """One raw column's source: the CSV column, its unit and an optional sign flip."""

    target: str
    column: str
    unit: str
    sign: float = 1.0
    airspeed: str = "true"  # V_m_s only: the kind of airspeed the column holds (converted to the true one)
    pressure: str = "dynamic"  # qbar_pa only: "impact" (q_c, converted to the dynamic pressure)


@dataclass(frozen=True)
class CsvMap:
    """A parsed map file."""

    path: str
    columns: tuple[ColumnMap, ...]
    vehicle_toml: str  # the text written to vehicle.toml
    vehicle_origin: str  # the file copied, or "inline [vehicle] table of MAP"
    delimiter: str = ","
    comment: str | None = None
    time_from_zero: bool = False
    decimal: str = "."

    def summary(self) -> str:
        rows = [f"map {self.path}: vehicle from {self.vehicle_origin}"]
        rows += [f"  {c.target} <- {'-' if c.sign < 0 else ''}{c.column!r} [{c.unit}"
                 f"{'' if c.airspeed == 'true' else ', ' + c.airspeed + ' airspeed'}]" for c in self.columns]
        return "\n".join(rows)


def load_csv_map(path: str | Path) -> CsvMap:
    """Read and check a map file; errors name the map file and the entry."""
    from schemas.telemetry import RAW_COLUMNS

    path = Path(path)
    src = str(path)
    try:
        doc = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ImportDataError(path, "no such map file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ImportDataError(path, f"not valid TOML: {exc}") from None
    unknown = set(doc) - {"csv", "columns", "vehicle"}
    if unknown:
        raise ImportDataError(path, f"unknown top-level keys {sorted(unknown)} (expected csv, columns, vehicle)")
    opts = doc.get("csv", {})
    if set(opts) - _CSV_KEYS:
        raise ImportDataError(path, f"[csv] has unknown keys {sorted(set(opts) - _CSV_KEYS)} "
                              f"(known: {', '.join(sorted(_CSV_KEYS))})")
    table = doc.get("columns")
    if not isinstance(table, dict) or not table:
        raise ImportDataError(path, "no [columns] table: map each raw column to a CSV column and its unit")
    missing = [c for c in RAW_COLUMNS if c not in table]
    if missing:
        raise ImportDataError(path, f"[columns] has no entry for the raw column(s) {missing} (every raw contract "
                              f"column is needed: {', '.join(RAW_COLUMNS)})", column=missing[0])
    entries = []
    for target, entry in table.items():
        if target not in TARGET_UNITS:
            raise ImportDataError(path, f"[columns] {target!r} is not a raw telemetry column (known: "
                                  f"{', '.join(TARGET_UNITS)})", column=target)
        if not isinstance(entry, dict) or not {"column", "unit"} <= set(entry) or set(entry) - _ENTRY_KEYS:
            raise ImportDataError(path, f"[columns] {target} must be {{ column = \"CSV header\", unit = \"...\" "
                                  f"[, sign = -1] }}, got {entry!r}", column=target)
        sign = entry.get("sign", 1)
        if sign not in (1, -1):
            raise ImportDataError(path, f"[columns] {target}: sign must be 1 or -1, got {sign!r}", column=target)
        try:  # the unit is checked now, before any data is read
            conversion(target, str(entry["unit"]), where=src)
        except UnitError as exc:
            raise ImportDataError(path, str(exc).removeprefix(f"{src}: "), column=target) from None
        entries.append(ColumnMap(target, str(entry["column"]), str(entry["unit"]), float(sign),
                                 _stated_kind(path, target, entry, "airspeed"),
                                 _stated_kind(path, target, entry, "pressure")))
    text, origin = _vehicle_text(doc.get("vehicle"), path)
    return CsvMap(path=src, columns=tuple(entries), vehicle_toml=text, vehicle_origin=origin,
                  delimiter=str(opts.get("delimiter", ",")), comment=opts.get("comment"),
                  time_from_zero=bool(opts.get("time_from_zero", False)), decimal=_decimal(opts, path))


@dataclass(frozen=True)
class _StatedKind:
    """A map key that says what a column holds when it is not what the raw column means: its
    column, key, the kinds (the first is the raw column's own meaning), the header tokens and
    words that read as another kind (then the key is required), and why it matters."""

    target: str
    key: str
    kinds: tuple[str, ...]
    tokens: frozenset
    words: tuple[str, ...]
    reads_as: str
    matters: str
    converted: str


_STATED_KINDS = (
    _StatedKind("V_m_s", "airspeed", AIRSPEED_KINDS,
                frozenset(_NOT_TRUE_AIRSPEED_TOKENS), _NOT_TRUE_AIRSPEED_WORDS,
                "an indicated, calibrated or equivalent airspeed, and aerosid needs the true airspeed",
                "taken for it, such a column makes the dynamic pressure low by about rho/rho_0: every coefficient "
                "x1.16 at 1500 m, x1.8 at 6 km",
                "converted with h_m and the mapped p_static_pa, T_total_K, rho_kg_m3"),
    _StatedKind("qbar_pa", "pressure", PRESSURE_KINDS, frozenset(_IMPACT_PRESSURE_TOKENS), _IMPACT_PRESSURE_WORDS,
                "an impact pressure q_c = p_t - p, and qbar_pa is the dynamic pressure 0.5 rho V^2",
                "q_c exceeds it by about 1 + M^2/4: every coefficient x0.85 at Mach 0.8",
                "converted with the mapped p_static_pa, else the US-1976 pressure at h_m"),
)


def _stated_kind(path: Path, target: str, entry: dict, key: str) -> str:
    """The map entry's `key` (_STATED_KINDS: V_m_s's airspeed, qbar_pa's pressure); its own column's
    only, one of its kinds, and required where the CSV header reads as another kind (KIAS for
    V_m_s, qc for qbar_pa)."""
    spec = next(k for k in _STATED_KINDS if k.key == key)
    kind = entry.get(key)
    if target != spec.target:
        if kind is not None:
            raise ImportDataError(path, f"[columns] {target}: {key} is a key of {spec.target} only", column=target)
        return spec.kinds[0]
    if kind is None:
        header = str(entry["column"]).lower()
        if set(re.split(r"[^a-z0-9]+", header)) & spec.tokens or any(w in header for w in spec.words):
            others = ", ".join(f'"{k}"' for k in spec.kinds[2:])
            raise ImportDataError(path, f"[columns] {target}: the CSV column {entry['column']!r} reads as "
                                  f"{spec.reads_as} ({spec.matters}). State what it holds: {key} = "
                                  f'"{spec.kinds[1]}"{f" (or {others})" if others else ""} ({spec.converted}) or '
                                  f'{key} = "{spec.kinds[0]}"', column=target)
        return spec.kinds[0]
    if kind not in spec.kinds:
        raise ImportDataError(path, f"[columns] {target}: {key} must be one of {', '.join(spec.kinds)}, got "
                              f"{kind!r}", column=target)
    return str(kind)


def _decimal(opts: dict, path: Path) -> str:
    """The [csv] decimal mark: "." or ","; a comma cannot also be the delimiter."""
    mark = opts.get("decimal", ".")
    if mark not in (".", ","):
        raise ImportDataError(path, f"[csv] decimal must be \".\" or \",\", got {mark!r}")
    if mark == "," and opts.get("delimiter", ",") == ",":
        raise ImportDataError(path, "[csv] decimal = \",\" needs another delimiter (delimiter = \";\")")
    return mark


def _vehicle_text(spec, map_path: Path) -> tuple[str, str]:
    """The vehicle file's text: a copy of the file `spec` names, or the inline table written out."""
    from aerosid.vehicles.vehicle import VehicleError, resolve_vehicle_path

    if spec is None:
        raise ImportDataError(map_path, "no vehicle: give `vehicle = \"FILE_OR_BUILTIN\"` (before the tables) or a "
                              "[vehicle] table in the vehicle-file layout (docs/vehicles.md)")
    if isinstance(spec, dict) and set(spec) == {"file"}:
        spec = spec["file"]
    if isinstance(spec, str):
        local = map_path.parent / spec
        try:
            source = local if local.is_file() else resolve_vehicle_path(spec)
        except VehicleError:
            raise ImportDataError(map_path, f"vehicle {spec!r}: no such file (relative to the map) or built-in "
                                  "vehicle") from None
        text = source.read_text()
        database = tomllib.loads(text).get("aero", {}).get("database")
        if database and not Path(database).is_absolute():  # keep the copy pointing at the original database
            text, n = re.subn(r'(?m)^(\s*database\s*=\s*)"[^"\n]*"', lambda m: m.group(1) + _toml_str(
                str((source.parent / database).resolve())), text, count=1)
            if n != 1:
                raise ImportDataError(map_path, f"vehicle {source}: cannot rewrite its relative [aero] database path")
        return f"# copied by `aerosid import csv` from {source}\n" + text, str(source)
    if isinstance(spec, dict):
        import tomli_w

        head = f"# written by `aerosid import csv` from the [vehicle] table of {map_path}\n"
        return head + tomli_w.dumps(spec), f"inline [vehicle] table of {map_path}"
    raise ImportDataError(map_path, f"vehicle must be a file name or a [vehicle] table, got {spec!r}")


def _toml_str(text: str) -> str:
    import json

    return json.dumps(text)


PARQUET_SUFFIXES = (".parquet", ".pq")


def import_csv(csv_path: str | Path, map_path: str | Path) -> ImportedFlight:
    """Convert a flight-test CSV to aerosid's raw contract with the map's columns and units.
    A Parquet table (suffix .parquet or .pq: a data system's own names, units and types) is
    read the same way; its numeric columns are taken as they are, a timestamp column (datetime
    type) as seconds since 1970-01-01 UTC, others as text (the CSV's readers)."""
    cmap = load_csv_map(map_path)
    csv_path = Path(csv_path)
    if not csv_path.is_file():
        raise ImportDataError(csv_path, "no such file")
    if csv_path.suffix.lower() in PARQUET_SUFFIXES:
        frame = _read_parquet_table(csv_path)
    else:
        try:
            frame = pd.read_csv(csv_path, sep=cmap.delimiter, comment=cmap.comment, dtype=str,
                                keep_default_na=False, skipinitialspace=True)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
            raise ImportDataError(csv_path, f"not a readable CSV ({exc})") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    convs: list[Conversion] = []
    data: dict[str, np.ndarray] = {}
    for entry in cmap.columns:
        if entry.column not in frame.columns:
            raise ImportDataError(csv_path, f"not found in the CSV (mapped to {entry.target} by {cmap.path}); the "
                                  f"CSV has {list(frame.columns)}", column=entry.column)
        values = _column_values(frame[entry.column], entry, csv_path, cmap.decimal)
        conv = conversion(entry.target, entry.unit, source=f"CSV column {entry.column!r}", sign=entry.sign,
                          where=cmap.path)
        if entry.target == "t_s":
            check_time(values, str(csv_path), entry.column)
            if cmap.time_from_zero:
                conv = replace(conv, offset=conv.offset - float(conv.apply(values[:1])[0]),
                               source=f"{conv.source} minus its first value")
        convs.append(conv)
        data[entry.target] = conv.apply(values)
    notes = (f"vehicle file from {cmap.vehicle_origin}", *_to_true_airspeed(data, cmap),
             *_to_dynamic_pressure(data, cmap))
    telemetry = pd.DataFrame(data)
    vehicle_name = str(tomllib.loads(cmap.vehicle_toml).get("name", "vehicle"))
    from aerosid.provenance import sha256_file

    return ImportedFlight(importer="csv", source=str(csv_path), telemetry=telemetry, vehicle_toml=cmap.vehicle_toml,
                          vehicle_name=vehicle_name, conversions=tuple(convs), notes=notes,
                          extra_metadata={"aerosid.map": cmap.path, "aerosid.map_sha256": sha256_file(cmap.path)})


def _to_true_airspeed(data: dict[str, np.ndarray], cmap: CsvMap) -> tuple[str, ...]:
    """Convert data["V_m_s"] in place when the map says it is not a true airspeed; the note
    the import records."""
    from aerosid.vehicles.airspeed import columns_to_true_airspeed

    kind = next(c.airspeed for c in cmap.columns if c.target == "V_m_s")
    if kind == "true":
        return ()
    data["V_m_s"], note = columns_to_true_airspeed(data, kind, f"the map's {kind} airspeed")
    return (note,)


def _to_dynamic_pressure(data: dict[str, np.ndarray], cmap: CsvMap) -> tuple[str, ...]:
    """Convert data["qbar_pa"] in place when the map says it is an impact pressure; the note."""
    from aerosid.vehicles.airspeed import dynamic_from_impact_pressure_pa
    from aerosid.vehicles.atmosphere import H_MAX_M, H_MIN_M, pressure_pa

    if next((c.pressure for c in cmap.columns if c.target == "qbar_pa"), "dynamic") == "dynamic":
        return ()
    qc = data["qbar_pa"]
    if "p_static_pa" in data:
        p, source = data["p_static_pa"], "the mapped p_static_pa"
    else:
        h = data["h_m"]
        inside = np.isfinite(h) & (h >= H_MIN_M) & (h <= H_MAX_M)
        p, source = np.full_like(h, np.nan), "the US-1976 pressure at h_m"
        p[inside] = pressure_pa(h[inside])
    ok = np.isfinite(qc) & (qc > 0) & np.isfinite(p) & (p > 0)
    out = np.where(np.isfinite(qc) & (qc > 0), np.nan, qc)  # a measured value that cannot be converted: empty
    out[ok] = dynamic_from_impact_pressure_pa(qc[ok], p[ok])
    data["qbar_pa"] = out
    return (f"qbar_pa: the map's impact pressure converted to the dynamic pressure with {source} "
            f"(aerosid.vehicles.airspeed.dynamic_from_impact_pressure_pa); {int((~ok & np.isfinite(qc)).sum())} "
            "row(s) without it left empty",)


def _column_values(column: pd.Series, entry, csv_path: Path, decimal: str) -> np.ndarray:
    """A mapped column as floats in its map unit: a Parquet table's numbers (and timestamps,
    already in s) as they are; the time column's clock times as seconds (its unit must be "s");
    text as numbers (_numbers)."""
    if column.dtype.kind == "f":
        return column.to_numpy()
    clock = _clock_times(column) if entry.target == "t_s" else None
    if clock is None:
        return _numbers(column, csv_path, entry.column, decimal)
    values, form = clock
    if entry.unit != "s":
        raise ImportDataError(csv_path, f"holds {form} (e.g. {str(column.iloc[0]).strip()!r}): its unit in the map "
                              f"must be \"s\", not {entry.unit!r}", column=entry.column)
    return values


def _epoch_seconds(stamps: pd.Series) -> np.ndarray:
    """UTC datetimes as seconds since 1970-01-01, whole seconds and their fraction apart (float64
    keeps 0.24 us at 1.7e9 s, not the ns); NaT -> NaN."""
    stamps = pd.to_datetime(stamps, utc=True)
    missing = stamps.isna().to_numpy()
    ns = stamps.fillna(pd.Timestamp(0, tz="UTC")).dt.as_unit("ns").astype("int64").to_numpy()
    return np.where(missing, np.nan, (ns // 1_000_000_000).astype(float) + (ns % 1_000_000_000) / 1e9)


def _read_parquet_table(path: Path) -> pd.DataFrame:
    """A Parquet table for the map: numeric columns as float64, datetime columns as seconds since
    1970-01-01 UTC (float64, whole seconds and their fraction apart as _clock_times), any other
    column as text."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise ImportDataError(path, f"not a readable Parquet file ({exc})") from None
    out = {}
    for name, column in zip(table.column_names, table.columns):
        kind = column.type
        if pa.types.is_timestamp(kind):
            out[name] = _epoch_seconds(column.to_pandas())
        elif pa.types.is_integer(kind) or pa.types.is_floating(kind):
            out[name] = column.to_numpy(zero_copy_only=False).astype(float)
        else:
            out[name] = column.to_pandas().astype(str).to_numpy()
    return pd.DataFrame(out)


def _clock_times(column: pd.Series) -> tuple[np.ndarray, str] | None:
    """The time column as seconds when it holds clock times rather than numbers: times of day
    ("13:52:30.060", IRIG-style "045:13:52:30.060" day-of-year first) -> seconds since midnight
    (of day 1); dates with times (ISO 8601, "2002-02-13 13:52:30.06") -> seconds since
    1970-01-01 UTC (the preprocessing counts a record's times from its first whole second,
    aerosid.preprocess.core.time_origin_s).  None when any cell is a plain number, or when not every cell
    parses as one kind of clock time (the number reader then names the first bad row)."""
    text = column.astype(str).str.strip()
    if text.empty or text.eq("").any() or pd.to_numeric(text, errors="coerce").notna().any():
        return None
    doy = text.str.fullmatch(r"\d{1,3}:\d{1,2}:\d{2}:\d{2}(\.\d*)?")
    if doy.all():  # IRIG-B: day of year, then the time of day
        day, rest = text.str.split(":", n=1).str[0].astype(int), text.str.split(":", n=1).str[1]
        tod = pd.to_timedelta(rest, errors="coerce")
        if tod.notna().all():
            return (day.to_numpy() - 1) * 86400.0 + tod.dt.total_seconds().to_numpy(), "day-of-year clock times"
        return None
    if text.str.fullmatch(r"\d{1,2}:\d{2}:\d{2}(\.\d*)?").all():
        tod = pd.to_timedelta(text, errors="coerce")
        return (tod.dt.total_seconds().to_numpy(), "times of day") if tod.notna().all() else None
    stamps = pd.to_datetime(text, errors="coerce", utc=True, format="ISO8601")
    if stamps.notna().all():
        return _epoch_seconds(stamps), "dates with times (UTC)"
    return None


def _numbers(column: pd.Series, csv_path: Path, name: str, decimal: str = ".") -> np.ndarray:
    """A CSV column as floats (decimal: the decimal mark): empty cells and NaN are dropouts; any
    other text is an error."""
    text = column.astype(str).str.strip()
    if decimal == ",":
        text = text.str.replace(",", ".", regex=False)
    empty = text.eq("") | text.str.lower().isin(["nan", "na", "null"])
    values = pd.to_numeric(text.where(~empty, None), errors="coerce").to_numpy(dtype=float)
    bad = np.flatnonzero(np.isnan(values) & ~empty.to_numpy())
    if bad.size:
        raise ImportDataError(csv_path, f"not a number at rows {bad[:10].tolist()} (e.g. {text.iloc[bad[0]]!r}; "
                              "row 0 is the first data line)", column=name)
    return values
