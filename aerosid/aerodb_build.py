"""Regenerate a built-in vehicle's aerodb.csv from its vehicle.toml:
``python -m aerosid.vehicles.aerodb_build seed-rlv``."""
from __future__ import annotations

import sys

from aerosid.vehicles.aerodb import tabulate
from aerosid.modelling.aeromodel import AeroModel
from aerosid.io import write_text_atomic
from aerosid.vehicles.vehicle import load_vehicle


def build_text(name: str) -> str:
    """The CSV text of the tabulated preflight database (%.12g, stable)."""
    vehicle = load_vehicle(name)
    return tabulate(AeroModel.preflight(vehicle)).to_csv(index=False, float_format="%.12g")


def main(argv: list[str] | None = None) -> int:
    for name in (argv if argv is not None else sys.argv[1:]) or ["seed-rlv"]:
        vehicle = load_vehicle(name)
        write_text_atomic(build_text(name), vehicle.database_path)
        print(f"wrote {vehicle.database_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
