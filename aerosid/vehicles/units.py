"""Unit conversion for imported flight data, through the ``pint`` units library.

Every raw telemetry column has one SI unit (:data:`TARGET_UNITS`); an importer
names the unit a source column was recorded in (``"deg"``, ``"deg/s"``, ``"g"``,
``"ft"``, ``"kt"``, ``"lbf/ft^2"``, ``"slug/ft^3"``, ...) and :func:`conversion`
returns the exact affine map ``si = factor * value + offset`` that pint computes,
as a frozen :class:`Conversion` that the importers record in the Parquet metadata.

Flight-test spellings that pint reads differently are translated first
(:data:`UNIT_ALIASES`): above all ``g`` is the standard gravity 9.80665 m/s^2 (as
accelerometer data use it), not pint's gram; ``fps``, ``dps``, ``psf``, ``kts``
and SIDPAC's labels (``slug-ft2``, ``ft/sec``) are read as what they mean.
"""
from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass

import numpy as np

from schemas.telemetry import UNITS

#: SI unit (pint spelling) of every column an importer may write: the raw contract
#: (schemas/telemetry.py RAW_COLUMNS), the vanes and the optional measured air data
#: and attitude columns (docs/real-flight.md).
TARGET_UNITS: dict[str, str] = {**UNITS, "phi_rad": "rad", "theta_rad": "rad"}

#: Flight-test and SIDPAC spellings -> pint spellings (matched on the whole,
#: stripped, lower-cased text; anything else goes to pint as written).
UNIT_ALIASES: dict[str, str] = {
    "g": "g0", "gs": "g0", "g's": "g0", "g0": "g0",
    "sec": "s", "secs": "s",
    "fps": "ft/s", "ft/sec": "ft/s", "ft/s": "ft/s",
    "dps": "deg/s", "deg/sec": "deg/s", "dps2": "deg/s^2", "deg/sec2": "deg/s^2",
    "rps": "rad/s", "rad/sec": "rad/s",
    "kt": "knot", "kts": "knot", "knots": "knot", "kn": "knot", "kias": "knot", "ktas": "knot",
    "psf": "lbf/ft^2", "lbf/ft2": "lbf/ft^2", "lb/ft2": "lbf/ft^2",
    "slug/ft3": "slug/ft^3", "slug-ft2": "slug*ft^2", "slug ft2": "slug*ft^2", "ft2": "ft^2",
    "degc": "degC", "degf": "degF", "degk": "K",
}


class UnitError(ValueError):
    """A unit that pint cannot read, or that does not convert to the column's SI unit."""

    def __init__(self, column: str, unit: str, message: str, where: str = ""):
        self.column, self.unit = column, unit
        prefix = f"{where}: " if where else ""
        super().__init__(f"{prefix}column {column!r}: unit {unit!r} {message}")


@functools.cache
def registry():
    """The shared pint registry (built once; pint's default definitions)."""
    import pint

    return pint.UnitRegistry()


def pint_spelling(unit: str) -> str:
    """The pint spelling of a unit as a flight-test file writes it (see UNIT_ALIASES)."""
    text = str(unit).strip()
    return UNIT_ALIASES.get(text.lower(), text)


@dataclass(frozen=True)
class Conversion:
    """One column's conversion: ``column = factor * source + offset`` (SI, from pint)."""

    column: str  # the raw telemetry column written
    source: str  # where the values came from (CSV column, SIDPAC fdata column)
    from_unit: str  # as the source names it
    to_unit: str  # the SI unit of `column`
    pint_unit: str  # how pint read from_unit
    factor: float
    offset: float = 0.0
    sign: float = 1.0  # a sign flip applied before the conversion (map option `sign = -1`)

    def apply(self, values) -> np.ndarray:
        """The source values in the column's SI unit."""
        return self.factor * (self.sign * np.asarray(values, dtype=float)) + self.offset

    def as_dict(self) -> dict:
        return asdict(self)

    def summary(self) -> str:
        sign = "-" if self.sign < 0 else ""
        off = f" {self.offset:+.12g}" if self.offset else ""
        return f"{self.column} = {self.factor:.12g} * {sign}{self.source} [{self.from_unit}]{off}  ({self.to_unit})"


def conversion(column: str, from_unit: str, source: str = "", sign: float = 1.0, where: str = "") -> Conversion:
    """The conversion of `from_unit` to `column`'s SI unit (TARGET_UNITS), computed by pint.

    Raises UnitError naming `where` (a file), the column and the unit when pint
    does not know the unit or it has another dimension than the column's.
    """
    if column not in TARGET_UNITS:
        raise UnitError(column, from_unit, f"cannot be converted: {column!r} is not a column an importer writes "
                        f"(known: {', '.join(TARGET_UNITS)})", where)
    if sign not in (1, -1, 1.0, -1.0):
        raise UnitError(column, from_unit, f"has sign {sign!r}; a sign must be 1 or -1", where)
    if not str(from_unit).strip():
        raise UnitError(column, from_unit, f"is empty; name the unit (SI: {TARGET_UNITS[column]})", where)
    import pint

    ureg = registry()
    spelled = pint_spelling(from_unit)
    to_unit = TARGET_UNITS[column]
    try:
        q0 = ureg.Quantity(0.0, spelled).to(to_unit).magnitude
        q1 = ureg.Quantity(1.0, spelled).to(to_unit).magnitude
    except pint.errors.DimensionalityError as exc:
        raise UnitError(column, from_unit, f"cannot be converted to {to_unit} ({exc})", where) from None
    except (pint.errors.UndefinedUnitError, pint.errors.DefinitionSyntaxError, AttributeError, TypeError,
            ValueError, AssertionError) as exc:
        raise UnitError(column, from_unit, f"is not a unit pint knows ({exc}); e.g. deg, deg/s, g, ft, ft/s, kt, "
                        "lbf/ft^2, slug/ft^3, degC", where) from None
    factor, offset = float(q1 - q0), float(q0)
    if not (math.isfinite(factor) and math.isfinite(offset)) or factor == 0.0:
        raise UnitError(column, from_unit, f"gives a degenerate conversion to {to_unit} (factor {factor})", where)
    if str(ureg.Quantity(1.0, spelled).units) in ("dimensionless", "") and to_unit != "1":
        # pint treats rad and deg as dimensionless: a bare number would pass silently
        raise UnitError(column, from_unit, f"is dimensionless; name the unit (e.g. deg or rad for {to_unit})", where)
    return Conversion(column=column, source=source, from_unit=str(from_unit), to_unit=to_unit,
                      pint_unit=str(ureg.Quantity(1.0, spelled).units), factor=factor, offset=offset,
                      sign=float(sign))


def to_si(value, from_unit: str, to_unit: str) -> float | np.ndarray:
    """`value` [from_unit] in `to_unit` through pint (for vehicle data: slug -> kg, in -> m, ...)."""
    out = registry().Quantity(np.asarray(value, dtype=float), pint_spelling(from_unit)).to(to_unit).magnitude
    return float(out) if np.ndim(out) == 0 else np.asarray(out)
