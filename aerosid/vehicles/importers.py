"""Imported flights: raw telemetry in aerosid's contract plus the vehicle file beside it.

``import_sidpac`` (aerosid/vehicles/sidpac.py) and ``import_csv``
(aerosid/vehicles/csv_import.py) return an :class:`ImportedFlight`;
:meth:`ImportedFlight.write` puts ``telemetry.parquet`` and ``vehicle.toml`` into a
folder, each atomically and checked before the rename (the telemetry against
``RawTelemetry``, the vehicle with ``load_vehicle``).  The Parquet metadata names
the vehicle file (``aerosid.vehicle_file``, relative to the telemetry), so
``aerosid run DIR/telemetry.parquet`` finds it, and records every unit conversion.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from aerosid.vehicles.units import Conversion

TELEMETRY_FILE = "telemetry.parquet"
VEHICLE_FILE = "vehicle.toml"


class ImportDataError(ValueError):
    """Input an importer cannot convert, named by file and (where it applies) column or variable."""

    def __init__(self, file: str | Path, message: str, column: str | None = None):
        self.file, self.column = str(file), column
        where = f"{self.file}" + (f": column {column!r}" if column else "")
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True)
class ImportedFlight:
    """One flight converted to aerosid's raw contract (SI, radians) and its vehicle file."""

    importer: str  # "sidpac" or "csv"
    source: str  # the file read
    telemetry: pd.DataFrame
    vehicle_toml: str  # the text of vehicle.toml
    vehicle_name: str
    conversions: tuple[Conversion, ...]
    notes: tuple[str, ...] = ()  # what the importer decided and why (also in the metadata)
    extra_metadata: dict = field(default_factory=dict)  # importer-specific aerosid.* entries

    @property
    def sample_rate_hz(self) -> float:
        t = self.telemetry["t_s"].to_numpy(float)
        return float(1.0 / np.median(np.diff(t))) if len(t) > 1 else float("nan")

    def metadata(self) -> dict[str, str]:
        """The Parquet key/value metadata of the telemetry file."""
        from aerosid.provenance import sha256_file

        meta = {
            "aerosid.kind": "raw_telemetry",
            "aerosid.importer": self.importer,
            "aerosid.source": self.source,
            "aerosid.vehicle": self.vehicle_name,
            "aerosid.vehicle_file": VEHICLE_FILE,
            "aerosid.sample_rate_hz": f"{self.sample_rate_hz:.6g}",
            "aerosid.conversions": json.dumps([c.as_dict() for c in self.conversions]),
            "aerosid.import_notes": json.dumps(list(self.notes)),
        }
        if Path(self.source).is_file():
            meta["aerosid.source_sha256"] = sha256_file(self.source)
        meta.update({k: str(v) for k, v in self.extra_metadata.items()})
        return meta

    def summary(self) -> str:
        t = self.telemetry["t_s"].to_numpy(float)
        extra = [c for c in self.telemetry.columns if c not in _CONTRACT]
        rows = [f"imported {self.source} ({self.importer}): {len(t)} samples, {t[0]:.2f}..{t[-1]:.2f} s at "
                f"{self.sample_rate_hz:.4g} Hz; optional columns {', '.join(extra) or 'none'}"]
        for name in ("V_m_s", "h_m", "rho_kg_m3"):
            if name in self.telemetry:
                rows.append(f"  mean {name} {np.nanmean(self.telemetry[name].to_numpy(float)):.4g}")
        rows += [f"  note: {n}" for n in self.notes]
        return "\n".join(rows)

    def write(self, out_dir: str | Path) -> dict[str, Path]:
        """Write DIR/vehicle.toml and DIR/telemetry.parquet (atomic, checked); returns their paths."""
        from aerosid.io import write_parquet_atomic, write_text_atomic
        from aerosid.vehicles.vehicle import VehicleError, load_vehicle
        from schemas.telemetry import RawTelemetry, validate

        out = Path(out_dir)
        tel_path, veh_target = out / TELEMETRY_FILE, out / VEHICLE_FILE
        validate(self.telemetry, RawTelemetry, str(tel_path))  # before anything is written

        def check_vehicle(tmp: Path) -> None:
            try:
                vehicle = load_vehicle(tmp)
            except VehicleError as exc:
                raise ImportDataError(self.source, f"the vehicle file for {veh_target} does not load: "
                                      f"[{exc.key}] {str(exc).split('] ', 1)[-1]}") from None
            if vehicle.air_data_source == "vanes":
                for col in (vehicle.alpha_column, vehicle.beta_column):
                    if col not in self.telemetry.columns:
                        raise ImportDataError(self.source, f"vehicle {vehicle.name} reads alpha and beta from vanes "
                                              "but the import has no such column", column=col)

        def check_telemetry(tmp: Path) -> None:
            validate(pd.read_parquet(tmp), RawTelemetry, str(tel_path))

        veh_path = write_text_atomic(self.vehicle_toml, veh_target, check=check_vehicle)
        write_parquet_atomic(self.telemetry, tel_path, metadata=self.metadata(), check=check_telemetry)
        return {"vehicle": veh_path, "telemetry": tel_path}


def _contract() -> tuple[str, ...]:
    from schemas.telemetry import RAW_COLUMNS

    return RAW_COLUMNS


_CONTRACT = _contract()


def check_time(t: np.ndarray, source: str, column: str) -> None:
    """Time must be finite and strictly increasing; name the first rows that are not."""
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ImportDataError(source, f"time is not finite at rows {bad[:10].tolist()}", column=column)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        raise ImportDataError(source, f"time does not increase at rows {(back + 1)[:10].tolist()} "
                              f"(t = {t[back[0]]!r} then {t[back[0] + 1]!r})", column=column)
