"""Thresholds of the preprocessing stage, per run and per sensor, and how they are
read from a vehicle file's ``[preprocess]`` table or from ``KEY=VALUE`` strings
(``aerosid run --preprocess``).  Every value is checked; errors name the key."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from schemas.telemetry import AIR_DATA_CHANNELS, CHANNELS, DEFAULT_SENTINELS

#: Default floor of the noise scale per channel, in the channel's unit (sigma of the
#: outlier test never goes below it: protects noise-free or constant channels).
DEFAULT_MIN_NOISE_SCALE: tuple[tuple[str, float], ...] = (
    ("ax_m_s2", 1e-3), ("ay_m_s2", 1e-3), ("az_m_s2", 1e-3),
    ("p_rad_s", 1e-4), ("q_rad_s", 1e-4), ("r_rad_s", 1e-4),
    ("d1_rad", 1e-5), ("d2_rad", 1e-5), ("d3_rad", 1e-5), ("d4_rad", 1e-5),
    ("V_m_s", 1e-3), ("h_m", 1e-2), ("alpha_vane_rad", 1e-5), ("beta_vane_rad", 1e-5),
    # measured air data: without a floor a constant column (SIDPAC logs one density per
    # manoeuvre) has noise scale 0 and every sample would be an "outlier"
    ("rho_kg_m3", 1e-6), ("qbar_pa", 1e-2), ("p_static_pa", 1e-2), ("T_total_K", 1e-4),
)

#: Default shortest segment [s] the pipeline smooths (not a preprocessing threshold, but
#: set in the same places: ``[preprocess] min_segment_s``, ``aerosid run --min-segment-s``).
DEFAULT_MIN_SEGMENT_S = 5.0

#: Settings a sensor (channel) may override: name -> (kind, description).
SENSOR_KEYS: dict[str, tuple[str, str]] = {
    "resolution": ("nonneg", "quantisation step in the channel's unit (0: continuous); default: detected"),
    "update_interval_s": ("positive", "time between the sensor's updates [s] (sample-and-hold); default: detected"),
    "min_noise_scale": ("nonneg", "floor of the noise scale of the outlier test, in the channel's unit"),
    "frozen_min_run": ("int>=2", "identical consecutive updates that make a frozen (stuck) run"),
    "frozen_max_still_s": ("positive", "for a channel at rest at its resolution: a still run longer than this "
                                       "[s] is frozen (default: never)"),
    "outlier_threshold_sigma": ("positive", "fixed outlier threshold [noise standard deviations] instead of the "
                                            "one from false_alarm and the record length"),
    "false_alarm": ("probability", "probability of one false outlier (or frozen run) in this channel per record"),
    "detect_frozen": ("bool", "run the frozen test on this channel"),
    "detect_outliers": ("bool", "run the outlier test on this channel"),
}

#: Global keys of ``[preprocess]`` / ``--preprocess`` (PreprocessParams fields) -> kind.
GLOBAL_KEYS: dict[str, str] = {
    "nominal_rate_hz": "positive", "snap_tolerance": "positive", "max_interp_gap_s": "positive",
    "outlier_window_s": "positive", "outlier_min_window": "int>=1", "outlier_threshold_sigma": "positive",
    "false_alarm": "probability", "noise_window_s": "positive", "frozen_min_run": "int>=2",
    "still_share": "probability", "max_time_gap_s": "positive",
}


class SettingsError(ValueError):
    """A preprocessing setting with an unknown key or a bad value; ``key`` names it."""

    def __init__(self, key: str, message: str):
        self.key, self.reason = key, message
        super().__init__(f"{key}: {message}")


def _check(key: str, kind: str, value: Any) -> Any:
    """The value converted to its kind, or SettingsError naming the key."""
    if kind == "bool":
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false", "yes", "no", "1", "0", "on", "off"):
            return value.lower() in ("true", "yes", "1", "on")
        raise SettingsError(key, f"must be true or false, got {value!r}")
    if isinstance(value, bool):
        raise SettingsError(key, f"must be a number, got {value!r}")
    try:
        num = float(value)
    except (TypeError, ValueError):
        raise SettingsError(key, f"must be a number, got {value!r}") from None
    if not math.isfinite(num):
        raise SettingsError(key, f"must be a finite number, got {value!r}")
    if kind.startswith("int"):
        if num != int(num):
            raise SettingsError(key, f"must be a whole number, got {value!r}")
        low = int(kind.removeprefix("int>="))
        if num < low:
            raise SettingsError(key, f"must be >= {low}, got {value!r}")
        return int(num)
    if kind == "positive" and num <= 0:
        raise SettingsError(key, f"must be > 0, got {value!r}")
    if kind == "nonneg" and num < 0:
        raise SettingsError(key, f"must be >= 0, got {value!r}")
    if kind == "probability" and not (0 < num <= 1):
        raise SettingsError(key, f"must be in (0, 1], got {value!r}")
    return num


def _normalise_sensors(sensors) -> tuple[tuple[str, tuple[tuple[str, Any], ...]], ...]:
    items = sensors.items() if isinstance(sensors, dict) else sensors
    out = []
    known = (*CHANNELS, *AIR_DATA_CHANNELS)
    for channel, settings in items:
        if channel not in known:
            raise SettingsError(str(channel), f"not a channel; channels are {', '.join(known)}")
        pairs = settings.items() if isinstance(settings, dict) else settings
        checked = []
        for k, v in pairs:
            if k not in SENSOR_KEYS:
                raise SettingsError(f"{channel}.{k}", f"unknown sensor setting; known: {', '.join(SENSOR_KEYS)}")
            checked.append((str(k), _check(f"{channel}.{k}", SENSOR_KEYS[k][0], v)))
        out.append((str(channel), tuple(sorted(checked))))
    return tuple(sorted(out))


@dataclass(frozen=True)
class PreprocessParams:
    """Thresholds of the preprocessing stage (all recorded in the output metadata).

    nominal_rate_hz:
        Sample rate of the grid [Hz]; ``None`` infers it as 1 / median interval.
    snap_tolerance:
        A raw timestamp further than this many grid steps (fraction of dt) from its
        nearest grid point is flagged ``TIME_JITTER`` (still placed there).
    max_interp_gap_s:
        Longest run of bad samples [s] (n samples last n*dt) that is linearly
        interpolated in ``<channel>_clean``; longer runs are left NaN (``LONG_GAP``)
        and all-channel ones are reported in ``long_gaps`` (the pipeline splits the
        flight there).  A held channel's limit is never below two update intervals.
    outlier_window_s:
        Length [s] of each one-sided median window of the spike test (h samples, at
        least ``outlier_min_window``; of updates for a held channel).  A genuine pulse
        must last longer than about half of it not to be taken for a burst of spikes.
    outlier_min_window:
        Minimum h [samples] at low sample rates.
    outlier_threshold_sigma:
        A fixed spike threshold [standard deviations of the test's residual]; ``None``
        (default) sets it per channel from ``false_alarm`` and the number of samples
        tested (:func:`aerosid.preprocess.detect.gaussian_threshold`: 5.2 for 6000
        samples, 5.7 for 10^5).
    false_alarm:
        Probability of one false outlier in a channel over the whole record on
        Gaussian noise (and of a frozen run by chance in a quantised channel).
    noise_window_s:
        Window [s] of the rolling robust noise-scale estimates.
    min_noise_scale:
        ``(channel, floor)`` pairs: floor of the noise scale in the channel's unit.
        The floor is also at least the channel's resolution.
    frozen_min_run:
        A run of at least this many identical consecutive *updates* (samples, for a
        channel updated every sample) is a stuck sensor (``FROZEN``; the first sample
        of the run is kept), in a channel whose updates change by more than its
        resolution.  Raised per channel when its updates repeat by chance.
    still_share:
        A quantised channel whose updates repeat the previous value more often than
        this (median over noise windows) rests at its resolution: its still runs are
        not frozen (unless ``frozen_max_still_s`` is set for that sensor).
    frozen_channels:
        Channels checked for frozen values (default the 12 contract channels).
    sensors:
        Per-sensor settings, ``{channel: {key: value}}`` (keys in ``SENSOR_KEYS``);
        they override the global values for that channel.
    sentinel_values:
        Values meaning "no data" (matched exactly or after a float32 round trip).
    max_time_gap_s:
        A time gap longer than this [s] is taken for a clock error (TelemetryError)
        rather than a dropout.
    rate_bounds_hz:
        Plausible grid rates [Hz]; an inferred or given rate outside raises
        TelemetryError (e.g. t in milliseconds).
    """

    nominal_rate_hz: float | None = None
    snap_tolerance: float = 0.25
    max_interp_gap_s: float = 0.5
    outlier_window_s: float = 0.05
    outlier_min_window: int = 5
    outlier_threshold_sigma: float | None = None
    false_alarm: float = 1e-3
    noise_window_s: float = 5.0
    min_noise_scale: tuple[tuple[str, float], ...] = DEFAULT_MIN_NOISE_SCALE
    frozen_min_run: int = 10
    still_share: float = 0.2
    frozen_channels: tuple[str, ...] = CHANNELS
    sensors: tuple = ()
    sentinel_values: tuple[float, ...] = DEFAULT_SENTINELS
    max_time_gap_s: float = 600.0
    rate_bounds_hz: tuple[float, float] = (1.0, 100_000.0)

    def __post_init__(self) -> None:
        def positive(name: str) -> None:
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
                raise ValueError(f"PreprocessParams.{name} must be a finite number > 0, got {v!r}")

        if self.nominal_rate_hz is not None:
            positive("nominal_rate_hz")
        if self.outlier_threshold_sigma is not None:
            positive("outlier_threshold_sigma")
        for name in ("max_interp_gap_s", "outlier_window_s", "noise_window_s", "max_time_gap_s", "false_alarm"):
            positive(name)
        if not (0 < self.snap_tolerance < 0.5):
            raise ValueError(f"PreprocessParams.snap_tolerance must be in (0, 0.5) grid steps, "
                             f"got {self.snap_tolerance!r}")
        if int(self.outlier_min_window) < 1 or int(self.frozen_min_run) < 2:
            raise ValueError("PreprocessParams.outlier_min_window must be >= 1 and frozen_min_run >= 2")
        if not (0 < self.false_alarm <= 1 and 0 < self.still_share <= 1):
            raise ValueError("PreprocessParams.false_alarm and still_share must be in (0, 1]")
        known = (*CHANNELS, *AIR_DATA_CHANNELS)
        unknown = [c for c in self.frozen_channels if c not in known]
        unknown += [c for c, _ in self.min_noise_scale if c not in known]
        if unknown:
            raise ValueError(f"PreprocessParams: unknown channel(s) {unknown}; channels are {list(known)}")
        lo, hi = self.rate_bounds_hz
        if not (0 < lo < hi):
            raise ValueError(f"PreprocessParams.rate_bounds_hz must be 0 < low < high, got {self.rate_bounds_hz}")
        try:
            object.__setattr__(self, "sensors", _normalise_sensors(self.sensors))
        except SettingsError as exc:
            raise ValueError(f"PreprocessParams.sensors: {exc}") from None
        for name in ("min_noise_scale", "frozen_channels", "sentinel_values", "rate_bounds_hz"):
            v = getattr(self, name)
            object.__setattr__(self, name, tuple(tuple(p) if isinstance(p, list) else p for p in v))

    @classmethod
    def from_dict(cls, d: dict | None) -> PreprocessParams:
        """From :meth:`to_dict`'s form or a settings dict (lists and mappings accepted)."""
        d = dict(d or {})
        if isinstance(d.get("min_noise_scale"), dict):
            d["min_noise_scale"] = tuple(d["min_noise_scale"].items())
        unknown = [k for k in d if k not in {f.name for f in dataclasses.fields(cls)}]
        if unknown:
            raise ValueError(f"PreprocessParams: unknown parameter(s) {unknown}")
        return cls(**d)

    def sensor(self, channel: str, key: str, default: Any = None) -> Any:
        """A sensor's own setting, else the global one of that name, else ``default``."""
        for c, pairs in self.sensors:
            if c == channel:
                for k, v in pairs:
                    if k == key:
                        return v
        if key == "min_noise_scale":
            return float(dict(self.min_noise_scale).get(channel, 0.0))
        if key == "detect_frozen":
            return channel in self.frozen_channels
        return getattr(self, key, default) if key in GLOBAL_KEYS else default

    def min_noise_scale_of(self, channel: str) -> float:
        return float(self.sensor(channel, "min_noise_scale"))

    def to_dict(self) -> dict:
        """JSON-friendly dict of the parameters."""
        d = dataclasses.asdict(self)
        d["min_noise_scale"] = dict(self.min_noise_scale)
        d["frozen_channels"] = list(self.frozen_channels)
        d["sentinel_values"] = list(self.sentinel_values)
        d["rate_bounds_hz"] = list(self.rate_bounds_hz)
        d["sensors"] = {c: dict(pairs) for c, pairs in self.sensors}
        return d


def parse_settings(table: dict) -> tuple[dict, float | None]:
    """A ``[preprocess]`` table (or the same built from ``KEY=VALUE`` strings) ->
    (PreprocessParams keyword arguments, min_segment_s or None).

    Global keys are in ``GLOBAL_KEYS`` plus ``min_segment_s``; a sub-table named after
    a channel holds that sensor's settings (``SENSOR_KEYS``).  Raises SettingsError."""
    kwargs: dict = {}
    sensors: dict = {}
    min_segment_s = None
    for key, value in table.items():
        if isinstance(value, dict):
            known = (*CHANNELS, *AIR_DATA_CHANNELS)
            if key not in known:
                raise SettingsError(key, f"a sub-table must be named after a channel ({', '.join(known)})")
            for k, v in value.items():
                if k not in SENSOR_KEYS:
                    raise SettingsError(f"{key}.{k}", f"unknown sensor setting; known: {', '.join(SENSOR_KEYS)}")
                sensors.setdefault(key, {})[k] = _check(f"{key}.{k}", SENSOR_KEYS[k][0], v)
        elif key == "min_segment_s":
            min_segment_s = _check(key, "positive", value)
        elif key in GLOBAL_KEYS:
            kwargs[key] = _check(key, GLOBAL_KEYS[key], value)
        else:
            raise SettingsError(key, "unknown setting; global keys: " + ", ".join([*GLOBAL_KEYS, "min_segment_s"])
                                + "; a channel's table (e.g. [preprocess.V_m_s]) takes: " + ", ".join(SENSOR_KEYS))
    if sensors:
        kwargs["sensors"] = sensors
    PreprocessParams.from_dict(kwargs)  # cross-checks (e.g. snap_tolerance < 0.5)
    return kwargs, min_segment_s


def parse_assignments(items: list[str] | tuple[str, ...]) -> dict:
    """``["false_alarm=1e-4", "V_m_s.resolution=0.05"]`` -> a ``[preprocess]``-like table
    (values stay strings; :func:`parse_settings` converts and checks them)."""
    table: dict = {}
    for item in items:
        key, sep, value = str(item).partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise SettingsError(str(item), "expected KEY=VALUE or CHANNEL.KEY=VALUE (e.g. false_alarm=1e-4, "
                                           "V_m_s.update_interval_s=0.2)")
        channel, dot, sub = key.partition(".")
        if dot:
            table.setdefault(channel, {})
            if not isinstance(table[channel], dict):
                raise SettingsError(key, f"{channel} is given both as a value and as a channel")
            table[channel][sub] = value
        else:
            table[key] = value
    return table


def merge_settings(base: dict, override: dict) -> dict:
    """PreprocessParams keyword arguments: ``override`` on top of ``base`` (sensor
    tables merged key by key)."""
    out = {**base, **{k: v for k, v in override.items() if k != "sensors"}}
    sensors = {c: dict(v) for c, v in (base.get("sensors") or {}).items()}
    for c, v in (override.get("sensors") or {}).items():
        sensors.setdefault(c, {}).update(v)
    if sensors:
        out["sensors"] = sensors
    return out
