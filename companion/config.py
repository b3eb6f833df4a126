"""Daemon configuration: defaults < TOML file < ``LANDFALL_*`` environment < command-line flags.

Every option lives in one section (``[mavlink]``, ``[sensors]``, ``[camera]``, ``[recovery]``, ``[alarms]``,
``[reasoner]``, ``[record]``, ``[log]``); ``deploy/companion.toml`` lists them all with units and defaults.
The environment variable for ``section.key`` is ``LANDFALL_<SECTION>_<KEY>`` in upper case, e.g.
``LANDFALL_RECOVERY_MAX_ROUNDS=6``. Environment values are text and are parsed to the option's type:
booleans accept ``true/false/1/0/yes/no/on/off``, lists are comma-separated (``1,2,3``; empty = empty
list), a sub-table such as ``recovery.rounds_by_criticality`` takes ``low=10,high=6,critical=3`` (the keys
given replace only those keys), and an empty value for an optional option (``record.dir``) means "none".

The MAVLink 2 signing key is read from the environment variable named by ``mavlink.signing_key_env``
(default ``LANDFALL_SIGNING_KEY``), which wins over a ``mavlink.signing_key`` in the file (allowed but
discouraged). The key is held as a :class:`pydantic.SecretStr`: ``repr``, ``str``, JSON dumps and error
messages never show it.

Errors are :class:`ConfigError` and name the option the way the user wrote it::

    companion.toml: recovery.max_rounds: must be >= 1 (got 0)
    LANDFALL_RECOVERY_MAX_ROUNDS: must be an integer (got 'ten')
    --sensors: must be HOST:PORT (got 'localhost')

Unknown options in the file, unknown ``LANDFALL_<SECTION>_*`` variables for a known section and unknown
override keys are rejected with the allowed names listed. Variables named by a ``*_env`` option (the
signing key's and the MQTT password's) are exempt, as is any ``LANDFALL_*`` name whose second word is
not a section.

Kept whole (about 700 lines): one schema, every section's options and checks beside the loader
that names them in errors; a section read apart from the loader's rules would not say what it accepts.
"""

from __future__ import annotations

import logging
import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, Self, get_args, get_origin

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    SecretStr,
    Strict,
    ValidationError,
    field_validator,
    model_validator,
)

__all__ = [
    "ENV_PREFIX",
    "OVERRIDE_FLAGS",
    "AlarmsConfig",
    "CompanionConfig",
    "ConfigError",
    "LogConfig",
    "LvlmProfileConfig",
    "MavlinkConfig",
    "ReasonerConfig",
    "RecordConfig",
    "RecoveryConfig",
    "RoundsByCriticality",
    "SearchWindow",
    "SensorsConfig",
    "env_var_name",
    "load_config",
]

ENV_PREFIX = "LANDFALL_"
#: Dotted option -> the daemon flag that sets it (used to name the option in errors).
OVERRIDE_FLAGS: Mapping[str, str] = {
    "mavlink.url": "--mavlink",
    "sensors.endpoint": "--sensors",
    "reasoner.name": "--reasoner",
    "record.dir": "--record",
    "log.level": "--log-level",
}
_LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")
_ENV_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_TRUE = frozenset({"1", "true", "yes", "on"})
_FALSE = frozenset({"0", "false", "no", "off"})

_log = logging.getLogger(__name__)


class ConfigError(ValueError):
    """A configuration value that cannot be used.

    Attributes:
        option: where the value came from, as the user wrote it: ``"companion.toml: recovery.max_rounds"``,
            ``"LANDFALL_RECOVERY_MAX_ROUNDS"`` or ``"--sensors"``.
        problem: what is wrong and what was expected, e.g. ``"must be >= 1 (got 0)"``.
    """

    def __init__(self, option: str, problem: str) -> None:
        super().__init__(f"{option}: {problem}")
        self.option = option
        self.problem = problem


class _Section(BaseModel):
    # Strict: a TOML file has types, so "10" for an integer is a mistake worth naming. Environment text is
    # parsed to the field's type before validation (see _parse_text).
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)


def _host_port(text: str) -> str:
    host, sep, port_text = text.rpartition(":")
    if not sep or not host.strip("[]") or not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise ValueError(f"must be HOST:PORT with a port in 1..65535 (got {text!r})")
    return text


def _env_name(name: str) -> str:
    if _ENV_NAME_RE.fullmatch(name) is None:
        raise ValueError(f"must be an environment variable name (got {name!r})")
    return name


EnvName = Annotated[str, AfterValidator(_env_name)]  # the name of a variable that holds a secret


class MavlinkConfig(_Section):
    """The MAVLink endpoint and our identity on it."""

    url: str = "udp:14550"
    component_id: int = Field(default=191, ge=1, le=255)
    vehicle_system_id: int = Field(default=0, ge=0, le=255)  # 0: learn from the first autopilot heartbeat
    signing_key_env: EnvName = "LANDFALL_SIGNING_KEY"
    signing_key: SecretStr | None = None  # hex text; resolved from signing_key_env when that is set
    heartbeat_hz: float = Field(default=1.0, gt=0, le=50)

    @field_validator("url")
    @classmethod
    def _check_url(cls, url: str) -> str:
        scheme, sep, rest = url.partition(":")
        _, _, port_text = rest.rpartition(":")
        if not sep or scheme not in ("udp", "udpin", "udpout") or not port_text.isdigit():
            raise ValueError(f"must be udp:PORT, udpin:HOST:PORT or udpout:HOST:PORT (got {url!r})")
        if not 0 < int(port_text) < 65536:
            raise ValueError(f"port must be in 1..65535 (got {url!r})")
        return url

    @field_validator("signing_key")
    @classmethod
    def _check_key(cls, key: SecretStr | None) -> SecretStr | None:
        # Never echo the key, not even in part.
        if key is None:
            return None
        text = key.get_secret_value().strip()
        if not text:
            raise ValueError("is empty: set 64 hex digits (a 32-byte key), or unset it to run unsigned")
        try:
            raw = bytes.fromhex(text)
        except ValueError:
            # Not chained, so that no traceback carries anything derived from the key.
            raise ValueError("must be 64 hex digits (a 32-byte key); it has non-hex characters") from None
        if len(raw) != 32:
            raise ValueError(f"must be 64 hex digits (a 32-byte key); got {len(text)} hex digits")
        return SecretStr(text)


class SensorsConfig(_Section):
    """The local sensor-stream socket (simbridge or the real sensor bridge)."""

    endpoint: str = "127.0.0.1:5600"  # "none": no sensor stream (a camera alone, ``[camera]``)
    frame_timeout_s: float = Field(default=10.0, gt=0)
    max_frame_age_s: float = Field(default=2.0, gt=0)

    @field_validator("endpoint")
    @classmethod
    def _check_endpoint(cls, endpoint: str) -> str:
        return endpoint if endpoint == "none" else _host_port(endpoint)


class CameraConfig(_Section):
    """A video camera (``companion --camera URL``, module companion.camera): the image comes from it; a
    LiDAR stays on the sensor stream, the rangefinder comes from the autopilot's DISTANCE_SENSOR."""

    url: str | None = None  # udp://[HOST]:PORT (RTP/H.264), rtsp://..., /dev/videoN or a video file
    info: Path | None = Field(default=None, strict=False)  # calibration: ROS camera_info or OpenCV YAML
    latency_ms: float = Field(default=100.0, ge=0, le=5000)  # capture to decoded, this computer's clock
    mount_rpy_deg: tuple[float, float, float] = Field(default=(0.0, 0.0, 0.0), strict=False)
    offset_frd_m: tuple[float, float, float] = Field(default=(0.0, 0.0, 0.0), strict=False)

    @field_validator("url")
    @classmethod
    def _check_url(cls, url: str | None) -> str | None:
        if url is None or url == "":
            return None
        from companion.camera import parse_camera_url

        parse_camera_url(url)  # CameraError (a ValueError) says what is wrong
        return url

    @field_validator("info", mode="before")
    @classmethod
    def _empty_is_none(cls, info: object) -> object:
        return None if info == "" else info

    @model_validator(mode="after")
    def _needs_calibration(self) -> CameraConfig:
        if self.url is not None and self.info is None:
            raise ValueError(
                "a camera needs its calibration: camera.info (--camera-info FILE), a ROS camera_info or "
                "OpenCV calibration YAML file"
            )
        for name in ("mount_rpy_deg", "offset_frd_m"):
            if not all(math.isfinite(v) for v in getattr(self, name)):
                raise ValueError(f"{name} must be finite numbers")
        return self


class _ByCriticality(_Section):
    """A value per alarm criticality (``low``, ``high``, ``critical`` fields of the subclass) that must
    not grow with it: a more urgent alarm never gets more."""

    @model_validator(mode="after")
    def _check_order(self) -> Self:
        low, high, critical = (getattr(self, k) for k in ("low", "high", "critical"))
        if not low >= high >= critical:
            raise ValueError(
                "must not grow with criticality (low >= high >= critical); "
                f"got low={low}, high={high}, critical={critical}"
            )
        return self


class RoundsByCriticality(_ByCriticality):
    """Round budget per alarm criticality; a critical alarm accepts a riskier site sooner."""

    low: int = Field(default=10, ge=1)
    high: int = Field(default=6, ge=1)
    critical: int = Field(default=3, ge=1)


class SearchWindow(_ByCriticality):
    """Seconds of the autopilot's clock after the alarm within which the search may start a new leg or
    round, per criticality: a critical alarm has little time, a GPS-spoofing alarm has minutes."""

    low: float = Field(default=480.0, ge=0)
    high: float = Field(default=300.0, ge=0)
    critical: float = Field(default=60.0, ge=0)


class RecoveryConfig(_Section):
    """The recovery loop (DESIGN.md section 2)."""

    max_rounds: int = Field(default=10, ge=1)
    rounds_by_criticality: RoundsByCriticality = RoundsByCriticality()
    descent_fraction: float = Field(default=0.8, gt=0, lt=1)
    final_land_m: float = Field(default=5.0, gt=0)
    arrival_tolerance_m: float = Field(default=0.5, gt=0)
    arrival_speed_m_s: float = Field(default=0.3, gt=0)
    move_timeout_s: float = Field(default=60.0, gt=0)
    move_timeout_s_per_m: float = Field(default=0.5, ge=0)
    explore_climb_m: float = Field(default=15.0, gt=0)
    explore_max_alt_m: float = Field(default=90.0, gt=0)
    blind_descent_agl_m: float = Field(default=70.0, gt=0)
    sensor_loss_s: float = Field(default=30.0, gt=0)
    link_loss_s: float = Field(default=60.0, gt=0)
    failsafe_grace_s: float = Field(default=6.0, ge=0)
    land_timeout_s: float = Field(default=120.0, gt=0)
    search_reserve_pct: float = Field(default=25.0, ge=0, le=100)
    search_window_s: SearchWindow = SearchWindow()
    search_agl_m: float = Field(default=75.0, gt=0)
    search_max_legs: int = Field(default=40, ge=0)


class PerceptionConfig(_Section):
    """Surface ID: the depth source and the flatness thresholds (companion/perception)."""

    depth: Literal["lidar", "depth-anything", "auto"] = "lidar"
    depth_model: Path | None = Field(default=None, strict=False)
    cell_px: int = Field(default=4, ge=1, le=32)
    window_cells: int = Field(default=5, ge=3, le=31)
    max_slope_deg: float = Field(default=8.0, gt=0, lt=90)
    max_roughness_m: float = Field(default=0.06, gt=0)
    min_area_m2: float = Field(default=30.0, gt=0)
    edge_margin_m: float = Field(default=2.0, ge=0)
    max_candidates: int = Field(default=5, ge=1, le=20)
    lidar_range_m: float = Field(default=100.0, gt=0)
    extend_with_image: bool = True
    strip_min_length_m: float = Field(default=45.0, gt=0)
    strip_min_aspect: float = Field(default=2.5, gt=1)

    @field_validator("window_cells")
    @classmethod
    def _odd(cls, window: int) -> int:
        if window % 2 == 0:
            raise ValueError(f"must be odd (got {window})")
        return window

    @field_validator("depth_model", mode="before")
    @classmethod
    def _empty_model_is_none(cls, value: object) -> object:
        return None if value == "" else value


class AlarmsConfig(_Section):
    """Which alarm sources the daemon watches besides explicit alarm commands."""

    watch_battery: bool = True
    battery_critical_pct: float = Field(default=15.0, ge=0, le=100)
    watch_failsafe_text: bool = True
    watch_gps: bool = True
    # Lax at the field so a TOML array becomes a tuple; the items stay strict integers.
    accept_from_system_ids: tuple[Annotated[int, Strict(), Field(ge=1, le=255)], ...] = Field(
        default=(), strict=False
    )


class LvlmProfileConfig(_Section):
    """One OpenAI-compatible model endpoint (``[reasoner.profiles.NAME]``). Every key is optional: over a
    built-in profile of the same name only the keys given change; a new name needs base_url and model."""

    base_url: str | None = Field(default=None, pattern=r"^https?://\S+$")
    model: str | None = Field(default=None, min_length=1)
    api_key_env: str | None = None  # "" = keyless (local servers)
    schema_variant: Literal["strict", "relaxed", "none"] | None = None
    max_side_px: int | None = Field(default=None, ge=64, le=4096)
    jpeg_quality: int | None = Field(default=None, ge=30, le=100)
    max_tokens: int | None = Field(default=None, ge=16)
    max_completion_tokens: int | None = Field(default=None, ge=16)
    reasoning_effort: Literal["minimal", "low", "medium", "high"] | None = None
    temperature: float | None = Field(default=None, ge=0, le=2)
    headers: dict[str, str] | None = None
    extra_body: dict[str, Any] | None = None
    attempt_timeout_s: float | None = Field(default=None, gt=0)
    max_attempts: int | None = Field(default=None, ge=1, le=10)

    @field_validator("api_key_env")
    @classmethod
    def _check_env_name(cls, name: str | None) -> str | None:
        if name and _ENV_NAME_RE.fullmatch(name) is None:
            raise ValueError(f"must be an environment variable name (got {name!r})")
        return name


_TIER_NAME = Annotated[str, Strict(), Field(min_length=1, pattern=r"^\S+$")]


class ReasonerConfig(_Section):
    """The reasoning tiers, their order per stage, deadlines and the confirmation rule
    (companion/reasoning; DESIGN.md section 8)."""

    name: str = Field(default="onboard", min_length=1, pattern=r"^\S+$")
    rank_fallbacks: tuple[_TIER_NAME, ...] = Field(default=(), strict=False)
    confirm_fallbacks: tuple[_TIER_NAME, ...] = Field(default=(), strict=False)
    rank_deadline_s: float = Field(default=10.0, gt=0)
    confirm_deadline_s: float = Field(default=6.0, gt=0)
    critical_deadline_factor: float = Field(default=0.5, gt=0, le=1)
    context: Literal["crop", "pad20", "pad30", "pad40", "pad50", "pad60", "full"] = "crop"
    hedge: str = ""
    hedge_after_s: float = Field(default=4.0, gt=0)
    override_lone_no_after: int = Field(default=2, ge=1)
    onboard_judge: Literal["cues", "landnet"] = "landnet"
    onboard_model: str = Field(default="landnet-s", min_length=1)
    profiles: dict[str, LvlmProfileConfig] = Field(default_factory=dict, strict=False)


class RecordConfig(_Section):
    """The flight record (``--record DIR``)."""

    dir: Path | None = Field(default=None, strict=False)
    max_mb: int = Field(default=500, ge=1)

    @field_validator("dir", mode="before")
    @classmethod
    def _empty_is_none(cls, value: object) -> object:
        # TOML has no null: an empty string means "no record", as an empty LANDFALL_RECORD_DIR does.
        return None if value == "" else value


class MqttConfig(_Section):
    """The ground-station feed (companion/ground.py): an MQTT broker the ground station also reads."""

    enabled: bool = False
    host: str = "127.0.0.1"
    port: int = Field(default=1883, ge=1, le=65535)
    username: str = ""
    password_env: EnvName = "LANDFALL_MQTT_PASSWORD"
    tls: bool = False
    topic_prefix: str = "landfall"
    vehicle_id: str = "drone1"
    telemetry_hz: float = Field(default=1.0, ge=0.1, le=10)
    queue_size: int = Field(default=256, ge=1)
    alarm_intake: bool = False
    keepalive_s: int = Field(default=30, ge=5, le=3600)
    thumbnail_width_px: int = Field(default=320, ge=32, le=1920)

    @field_validator("topic_prefix", "vehicle_id")
    @classmethod
    def _topic_part(cls, text: str) -> str:
        if not text or any(c in text for c in "+#\0") or text.startswith("/") or text.endswith("/"):
            raise ValueError(f"must be a non-empty topic part without '+', '#' or outer '/' (got {text!r})")
        return text


class LogConfig(_Section):
    level: str = "INFO"

    @field_validator("level")
    @classmethod
    def _check_level(cls, level: str) -> str:
        if level.upper() not in _LOG_LEVELS:
            raise ValueError(f"must be one of {', '.join(_LOG_LEVELS)} (got {level!r})")
        return level.upper()


class CompanionConfig(_Section):
    """The whole daemon configuration, one frozen model per section."""

    mavlink: MavlinkConfig = MavlinkConfig()
    sensors: SensorsConfig = SensorsConfig()
    camera: CameraConfig = CameraConfig()
    recovery: RecoveryConfig = RecoveryConfig()
    perception: PerceptionConfig = PerceptionConfig()
    alarms: AlarmsConfig = AlarmsConfig()
    reasoner: ReasonerConfig = ReasonerConfig()
    record: RecordConfig = RecordConfig()
    mqtt: MqttConfig = MqttConfig()
    log: LogConfig = LogConfig()

    @model_validator(mode="after")
    def _needs_a_view(self) -> CompanionConfig:
        if self.sensors.endpoint == "none" and self.camera.url is None:
            raise ValueError(
                "sensors.endpoint is 'none' and there is no camera: the companion needs a sensor stream "
                "(--sensors HOST:PORT) or a camera (--camera URL) to see where it lands"
            )
        return self

    def signing_key(self) -> bytes | None:
        """The 32-byte MAVLink 2 signing key, or ``None`` to run unsigned (validated at load)."""
        key = self.mavlink.signing_key
        return None if key is None else bytes.fromhex(key.get_secret_value())

    def mqtt_password(self, env: Mapping[str, str]) -> str | None:
        """The broker password from the variable named by ``mqtt.password_env`` (never from the file)."""
        return env.get(self.mqtt.password_env) or None

    def rounds_for(self, criticality: Literal["low", "high", "critical"]) -> int:
        """Round budget for an alarm: the criticality's budget, capped by ``recovery.max_rounds``."""
        by = self.recovery.rounds_by_criticality
        return min(
            self.recovery.max_rounds, {"low": by.low, "high": by.high, "critical": by.critical}[criticality]
        )


def env_var_name(dotted: str) -> str:
    """``"recovery.max_rounds"`` -> ``"LANDFALL_RECOVERY_MAX_ROUNDS"``."""
    return ENV_PREFIX + dotted.replace(".", "_").upper()


# --- loading -----------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Origin:
    """Where a value came from: ``name`` (file path, variable or flag) set the option ``anchor``."""

    kind: Literal["file", "env", "flag"]
    name: str
    anchor: tuple[str, ...]


_PRECEDENCE = {"file": 1, "env": 2, "flag": 3}


def _fmt_loc(loc: tuple[str | int, ...]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out


def _label(origin: _Origin | None, loc: tuple[str | int, ...]) -> str:
    if origin is None:
        return f"{_fmt_loc(loc)} (default)"
    if origin.kind == "file":
        return f"{origin.name}: {_fmt_loc(loc)}"
    rest = loc[len(origin.anchor) :]
    if not rest:
        return origin.name
    # A list item reads LANDFALL_X[1]; a sub-key reads LANDFALL_X (critical).
    return (
        f"{origin.name}{_fmt_loc(rest)}" if isinstance(rest[0], int) else f"{origin.name} ({_fmt_loc(rest)})"
    )


def _find_origin(origins: Mapping[tuple[str, ...], _Origin], loc: tuple[str | int, ...]) -> _Origin | None:
    keys = tuple(str(p) for p in loc)
    for n in range(len(keys), 0, -1):
        if keys[:n] in origins:
            return origins[keys[:n]]
    # A model-level check (no leaf of its own): blame the highest-precedence source below it.
    below = [o for k, o in origins.items() if k[: len(keys)] == keys]
    return max(below, key=lambda o: _PRECEDENCE[o.kind], default=None)


def _model_at(path: tuple[str | int, ...]) -> type[BaseModel] | None:
    model: type[BaseModel] = CompanionConfig
    parts = list(path)
    while parts:
        field = model.model_fields.get(str(parts.pop(0)))
        sub = field.annotation if field is not None else None
        if get_origin(sub) is dict and parts:  # a table of named tables: skip the name
            sub = get_args(sub)[1]
            parts.pop(0)
        if not (isinstance(sub, type) and issubclass(sub, BaseModel)):
            return None
        model = sub
    return model


def _problem(error: Mapping[str, Any]) -> str:
    kind = error["type"]
    loc = tuple(error["loc"])
    ctx = error.get("ctx") or {}
    secret = any(str(p) == "signing_key" for p in loc)
    got = "" if secret else f" (got {error['input']!r})"
    if kind == "extra_forbidden":
        parent = _model_at(loc[:-1])
        allowed = ", ".join(parent.model_fields) if parent is not None else "?"
        return f"unknown {'section' if len(loc) == 1 else 'option'} (allowed: {allowed})"
    simple = {
        "int_type": "must be an integer",
        "int_parsing": "must be an integer",
        "int_from_float": "must be an integer",
        "float_type": "must be a number",
        "float_parsing": "must be a number",
        "finite_number": "must be a finite number",
        "bool_type": "must be true or false",
        "bool_parsing": "must be true or false",
        "string_type": "must be a string",
        "path_type": "must be a path (a string)",
        "tuple_type": "must be a list",
        "list_type": "must be a list",
        "model_type": "must be a table",
        "dict_type": "must be a table",
        "model_attributes_type": "must be a table",
        "string_too_short": "must not be empty",
        "string_pattern_mismatch": "must be one word (no spaces)",
    }
    bounds = {
        "greater_than": (">", "gt"),
        "greater_than_equal": (">=", "ge"),
        "less_than": ("<", "lt"),
        "less_than_equal": ("<=", "le"),
    }
    if kind in simple:
        return simple[kind] + got
    if kind in bounds:
        op, key = bounds[kind]
        bound = ctx.get(key)
        # Pydantic widens the bound to the field's type (0 -> 0.0); show it as the docs write it.
        if isinstance(bound, float) and bound.is_integer():
            bound = int(bound)
        return f"must be {op} {bound}{got}"
    if kind == "value_error":
        return str(ctx.get("error", error["msg"]))
    return str(error["msg"]) + got


def _parse_text(annotation: Any, text: str, secret: bool) -> Any:
    """Environment or flag text -> a value of the field's type; ``ValueError`` says what was expected."""
    got = "" if secret else f" (got {text!r})"
    args = get_args(annotation)
    if get_origin(annotation) is not None and type(None) in args:  # X | None
        if text == "" and not secret:
            return None
        annotation = next(a for a in args if a is not type(None))
    if annotation is bool:
        if text.strip().lower() in _TRUE:
            return True
        if text.strip().lower() in _FALSE:
            return False
        raise ValueError(f"must be true or false{got}")
    if annotation is int:
        try:
            return int(text.strip())
        except ValueError as exc:
            raise ValueError(f"must be an integer{got}") from exc
    if annotation is float:
        try:
            return float(text.strip())
        except ValueError as exc:
            raise ValueError(f"must be a number{got}") from exc
    if get_origin(annotation) is tuple:
        items = [t.strip() for t in text.split(",")] if text.strip() else []
        if get_args(get_args(annotation)[0])[:1] == (str,):  # tuple[Annotated[str, ...], ...]
            return tuple(items)
        try:
            return tuple(int(t) for t in items)
        except ValueError as exc:
            raise ValueError(f"must be a comma-separated list of integers{got}") from exc
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        table: dict[str, Any] = {}
        for item in filter(None, (t.strip() for t in text.split(","))):
            key, sep, value = item.partition("=")
            field = annotation.model_fields.get(key.strip())
            if not sep or field is None:
                allowed = ", ".join(f"{k}=..." for k in annotation.model_fields)
                raise ValueError(f"must be a comma-separated list of {allowed}{got}")
            table[key.strip()] = _parse_text(field.annotation, value.strip(), secret)
        return table
    if annotation is Path:
        return Path(text)
    return text  # str, SecretStr


def _field_annotation(section: str, key: str) -> Any:
    model = _model_at((section,))
    field = model.model_fields.get(key) if model is not None else None
    return None if field is None else field.annotation


def _merge(
    into: dict[str, Any],
    values: Mapping[str, Any],
    origins: dict[tuple[str, ...], _Origin],
    make: Any,
    prefix: tuple[str, ...] = (),
) -> None:
    """Deep-merge ``values`` into ``into``, recording ``make(path)`` as the origin of every leaf."""
    for key, value in values.items():
        path = (*prefix, key)
        if isinstance(value, Mapping):
            sub = into.get(key)
            if not isinstance(sub, dict):
                sub = into[key] = {}
            _merge(sub, value, origins, make, path)
        else:
            into[key] = value
            for stale in [k for k in origins if k[: len(path)] == path]:
                del origins[stale]
            origins[path] = make(path)


def _read_file(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as f:
            data = tomllib.load(f)
    except OSError as exc:
        raise ConfigError(str(path), f"cannot read the file: {exc.strerror or exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(path), f"invalid TOML: {exc}") from exc
    except UnicodeDecodeError as exc:  # found by fuzzing (atheris): TOML files are UTF-8
        raise ConfigError(
            str(path), f"not UTF-8 text: byte {exc.start} is 0x{exc.object[exc.start]:02x}"
        ) from exc
    for section, table in data.items():
        if not isinstance(table, dict):
            if section in CompanionConfig.model_fields:
                raise ConfigError(f"{path}: {section}", f"must be a table ([{section}]), got {table!r}")
            allowed = ", ".join(CompanionConfig.model_fields)
            raise ConfigError(f"{path}: {section}", f"unknown section (allowed: {allowed})")
    return data


def _read_env(env: Mapping[str, str]) -> tuple[dict[str, Any], dict[str, str], list[str]]:
    """Parse ``LANDFALL_<SECTION>_<KEY>`` variables; returns (values, variable per option, unknown names)."""
    values: dict[str, Any] = {}
    names: dict[str, str] = {}
    unknown: list[str] = []
    for section in CompanionConfig.model_fields:
        model = _model_at((section,))
        if model is None:
            continue
        head = f"{ENV_PREFIX}{section.upper()}_"
        known = {env_var_name(f"{section}.{key}"): key for key in model.model_fields}
        for var in sorted(v for v in env if v.startswith(head)):
            key = known.get(var)
            if key is None:
                unknown.append(var)
                continue
            try:
                parsed = _parse_text(_field_annotation(section, key), env[var], secret=key == "signing_key")
            except ValueError as exc:
                raise ConfigError(var, str(exc)) from exc
            values.setdefault(section, {})[key] = parsed
            names[f"{section}.{key}"] = var
    return values, names, unknown


def _all_options() -> list[str]:
    sections = ((s, _model_at((s,))) for s in CompanionConfig.model_fields)
    return [f"{s}.{k}" for s, model in sections if model is not None for k in model.model_fields]


def _read_overrides(overrides: Mapping[str, Any]) -> dict[str, Any]:
    values: dict[str, Any] = {}
    for dotted, value in overrides.items():
        if value is None:  # the flag was not given
            continue
        section, _, key = dotted.partition(".")
        annotation = _field_annotation(section, key)
        label = OVERRIDE_FLAGS.get(dotted, f"override {dotted}")
        if annotation is None:
            allowed = ", ".join(_all_options())
            raise ConfigError(label, f"unknown option (allowed: {allowed})")
        if isinstance(value, str) and annotation is not str:
            try:
                value = _parse_text(annotation, value, secret=key == "signing_key")
            except ValueError as exc:
                raise ConfigError(label, str(exc)) from exc
        values.setdefault(section, {})[key] = value
    return values


def load_config(
    path: Path | None,
    env: Mapping[str, str],
    overrides: Mapping[str, Any],
    *,
    logger: logging.Logger | None = None,
) -> CompanionConfig:
    """Build the configuration: defaults < ``path`` (TOML) < ``env`` < ``overrides``.

    Args:
        path: the TOML file (``--config``), or ``None`` for none.
        env: the environment, usually ``os.environ``.
        overrides: dotted option -> value from flags, e.g. ``{"sensors.endpoint": "127.0.0.1:5601"}``;
            ``None`` values mean "flag not given". Text is parsed to the option's type.
        logger: where to warn about a signing key kept in the file.

    Raises:
        ConfigError: the first bad value, naming its option where it was set.
    """
    log = logger or _log
    merged: dict[str, Any] = {}
    origins: dict[tuple[str, ...], _Origin] = {}
    if path is not None:
        file_values = _read_file(path)
        _merge(merged, file_values, origins, lambda p: _Origin("file", str(path), ()))
    env_values, env_names, unknown_env = _read_env(env)
    _merge(merged, env_values, origins, lambda p: _Origin("env", env_names[".".join(p[:2])], p[:2]))
    flag_values = _read_overrides(overrides)
    _merge(
        merged,
        flag_values,
        origins,
        lambda p: _Origin("flag", OVERRIDE_FLAGS.get(".".join(p[:2]), f"override {'.'.join(p[:2])}"), p[:2]),
    )

    mavlink = merged.get("mavlink", {})
    key_env = mavlink.get("signing_key_env", MavlinkConfig.model_fields["signing_key_env"].default)
    if isinstance(key_env, str) and key_env in env:
        mavlink = merged.setdefault("mavlink", {})
        mavlink["signing_key"] = env[key_env]
        origins[("mavlink", "signing_key")] = _Origin("env", key_env, ("mavlink", "signing_key"))
    mqtt = merged.get("mqtt", {})
    password_env = mqtt.get("password_env", MqttConfig.model_fields["password_env"].default)
    for var in unknown_env:
        if var not in (key_env, password_env):
            section = var[len(ENV_PREFIX) :].split("_", 1)[0].lower()
            model = _model_at((section,))
            allowed = ", ".join(env_var_name(f"{section}.{k}") for k in (model.model_fields if model else ()))
            raise ConfigError(var, f"unknown option (allowed: {allowed})")

    try:
        config = CompanionConfig.model_validate(merged)
    except ValidationError as exc:
        error = exc.errors(include_url=False)[0]
        loc = tuple(error["loc"])
        # Not chained: a ValidationError repeats its raw input, which may be the signing key.
        raise ConfigError(_label(_find_origin(origins, loc), loc), _problem(error)) from None

    key_origin = origins.get(("mavlink", "signing_key"))
    if key_origin is not None and key_origin.kind == "file":
        log.warning(
            "%s: mavlink.signing_key: a key in the file is discouraged; set %s in the environment instead",
            key_origin.name,
            config.mavlink.signing_key_env,
        )
    return config
