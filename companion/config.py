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

The sections, their options and their checks are in :mod:`companion.config_schema`; this module reads
the sources, merges them and turns a failed check into a :class:`ConfigError` naming its source.
"""

from __future__ import annotations

import logging
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args, get_origin

from pydantic import BaseModel, ValidationError

from companion.config_schema import CompanionConfig, MavlinkConfig, MqttConfig

__all__ = ["ENV_PREFIX", "OVERRIDE_FLAGS", "ConfigError", "env_var_name", "load_config"]

ENV_PREFIX = "LANDFALL_"
#: Dotted option -> the daemon flag that sets it (used to name the option in errors).
OVERRIDE_FLAGS: Mapping[str, str] = {
    "mavlink.url": "--mavlink",
    "sensors.endpoint": "--sensors",
    "reasoner.name": "--reasoner",
    "record.dir": "--record",
    "log.level": "--log-level",
}
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
