"""The companion's configuration schema: one frozen pydantic model per section (``[mavlink]``,
``[sensors]``, ``[camera]``, ``[recovery]``, ``[perception]``, ``[alarms]``, ``[reasoner]``, ``[record]``,
``[mqtt]``, ``[log]``) with its options, defaults, bounds and checks, and :class:`CompanionConfig`, the
whole of it. ``deploy/companion.toml`` lists every option with its unit and default.

Values are checked strictly (a TOML file has types: ``"10"`` for an integer is a mistake worth naming);
:func:`companion.config.load_config` builds a :class:`CompanionConfig` from the file, the environment and
the flags, and names the option where a check here fails.

**Every default is written here, once.** The parts that fly keep their own frozen dataclasses
(:class:`~companion.recovery.RecoveryParams`, :class:`~companion.recovery.search_plan.SearchLimits`,
:class:`~companion.perception.surface_id.SurfaceParams`, the depth sources) and their field names: the
recovery, its tests, the evaluation and the benchmarks build them with a value or two changed, some
outside what a file may set (``sensor_loss_s=0``), and they also hold what no key sets (the depth source
object, the search's pace). A field that is a key reads its default from :data:`DEFAULTS`
(``final_land_m: float = DEFAULTS.recovery.final_land_m``), and
:meth:`RecoveryParams.from_config <companion.recovery.RecoveryParams.from_config>` builds them all from a
loaded configuration: a field named as a key of its section takes that key's value
(:meth:`_Section.values_for`); the few that differ (the per-criticality tables, the ``search_*`` keys of
``SearchLimits``, ``reasoner.context``, ``perception.lidar_range_m``) are mapped there by name. The
sections are not the runtime types themselves: their bounds would refuse the tests' values, and the
per-criticality tables the recovery indexes by :class:`~companion.alarms.Criticality` would change shape.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal, Self

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    SecretStr,
    Strict,
    field_validator,
    model_validator,
)

from companion.alarms import Criticality
from landfall_link.mavlink import LinkUrl, LinkUrlError

__all__ = [
    "DEFAULTS",
    "AlarmsConfig",
    "CameraConfig",
    "CompanionConfig",
    "LogConfig",
    "LvlmProfileConfig",
    "MavlinkConfig",
    "MqttConfig",
    "PerceptionConfig",
    "ReasonerConfig",
    "RecordConfig",
    "RecoveryConfig",
    "RoundsByCriticality",
    "SearchWindow",
    "SensorsConfig",
]

_LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")
_ENV_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class _Section(BaseModel):
    # Strict: a TOML file has types, so "10" for an integer is a mistake worth naming. Environment text is
    # parsed to the field's type before validation (companion.config's _parse_text).
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)

    def values_for(self, params: type[Any]) -> dict[str, Any]:
        """This section's values for the fields of the dataclass ``params`` named as its keys: such a
        field is that key (its default is the key's, through :data:`DEFAULTS`)."""
        keys = type(self).model_fields
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(params) if f.name in keys}


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


def _none_if_empty(value: object) -> object:
    # TOML has no null: an empty string means "none", as an empty environment variable does.
    return None if value == "" else value


OptionalPath = Annotated[Path | None, BeforeValidator(_none_if_empty)]  # "" is None


class MavlinkConfig(_Section):
    """The MAVLink endpoint and our identity on it."""

    url: str = "udp:14550"
    component_id: int = Field(default=191, ge=1, le=255)
    vehicle_system_id: int = Field(default=0, ge=0, le=255)  # 0: learn from the first autopilot heartbeat
    signing_key_env: EnvName = "LANDFALL_SIGNING_KEY"
    signing_key: SecretStr | None = None  # hex text; resolved from signing_key_env when that is set
    heartbeat_hz: float = Field(default=1.0, gt=0, le=50)
    # where settings changed over MAVLink's parameter protocol are kept (companion/params.py); "": not
    params_file: str = ""

    @field_validator("url")
    @classmethod
    def _check_url(cls, url: str) -> str:
        try:
            parsed = LinkUrl.parse(url)
        except LinkUrlError as exc:
            raise ValueError(f"{exc.problem} (got {url!r})") from None
        if parsed.mode != "serial" and parsed.port == 0:  # any free port: for a test's link, not a daemon
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

    endpoint: str = "127.0.0.1:5601"  # "none": no sensor stream (a camera alone, ``[camera]``)
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
    info: OptionalPath = Field(default=None, strict=False)  # calibration: ROS camera_info or OpenCV YAML
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

    def per_criticality(self) -> dict[Criticality, Any]:
        """The values keyed by :class:`~companion.alarms.Criticality`, as the recovery reads them."""
        return {c: getattr(self, c.name.lower()) for c in Criticality}


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
    people_margin_m: float = Field(default=10.0, ge=0)
    people_wait_s: float = Field(default=20.0, ge=0)

    def rounds(self) -> dict[Criticality, int]:
        """The round budget per criticality, each capped by ``max_rounds``."""
        return {c: min(self.max_rounds, n) for c, n in self.rounds_by_criticality.per_criticality().items()}


class PerceptionConfig(_Section):
    """Surface ID: the depth source and the flatness thresholds (companion/perception)."""

    depth: Literal["lidar", "depth-anything", "auto"] = "lidar"
    depth_model: OptionalPath = Field(default=None, strict=False)
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
    # the operator's controls (companion/operator.py): the mode a cancelled recovery leaves the vehicle
    # in, and an RC switch that inhibits every alarm (channel 0: none)
    cancel_mode: Literal["hold", "land", "rtl"] = "hold"
    inhibit_rc_channel: int = Field(default=0, ge=0, le=18)
    inhibit_pwm_us: tuple[Annotated[int, Strict(), Field(ge=800, le=2200)], ...] = Field(
        default=(1800, 2200), strict=False, min_length=2, max_length=2
    )

    @field_validator("inhibit_pwm_us")
    @classmethod
    def _check_band(cls, band: tuple[int, ...]) -> tuple[int, ...]:
        if band[0] > band[1]:
            raise ValueError(f"must be [low, high] with low <= high (got {list(band)})")
        return band


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
    onboard_model: str = Field(default="landnet-e", min_length=1)
    # open ground among buildings (a lawn, a sports field, a pasture) is a site like a roof when its
    # surface is at least this large and the site this far from its edge (docs/reasoning.md)
    open_ground_area_m2: float = Field(default=600.0, ge=0)
    open_ground_edge_m: float = Field(default=10.0, ge=0)
    profiles: dict[str, LvlmProfileConfig] = Field(default_factory=dict, strict=False)


class RecordConfig(_Section):
    """The flight record (``--record DIR``)."""

    dir: OptionalPath = Field(default=None, strict=False)  # "": no record
    max_mb: int = Field(default=500, ge=1)


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
        return self.recovery.rounds()[Criticality.parse(criticality)]


#: Every option at its default: where the runtime parameters take theirs (module docstring).
DEFAULTS = CompanionConfig()
