"""Named reasoning tiers: the built-in LVLM profiles, the config's own, and the cascade built from them.

``--reasoner NAME`` (``reasoner.name``) picks the first tier of both stages: ``onboard`` or an LVLM
profile. ``reasoner.rank_fallbacks`` / ``confirm_fallbacks`` name the tiers that follow it per stage
(e.g. a cloud model, then an edge model); the onboard tier always answers last, so a stage always ends
with an answer. Profiles are the built-ins below plus ``[reasoner.profiles.NAME]`` tables, whose keys
override a built-in of the same name field by field or define a new one (``base_url`` and ``model``
then required). Keys come from the environment variable each profile names, never from the file.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from companion.config import ConfigError
from companion.config_schema import CompanionConfig, LvlmProfileConfig, ReasonerConfig
from companion.reasoning.base import Reasoner
from companion.reasoning.cascade import Cascade, CascadeParams, Hedged
from companion.reasoning.landnet import LandNet, LandNetError
from companion.reasoning.lvlm import LvlmProfile, LvlmReasoner
from companion.reasoning.onboard import OnboardReasoner
from companion.reasoning.onboard_params import ConfirmParams

if TYPE_CHECKING:
    import httpx

__all__ = ["BUILTIN_PROFILES", "ONBOARD", "build_cascade", "resolve_profile", "secrets", "tier_names"]

_log = logging.getLogger(__name__)

ONBOARD = "onboard"

_OPENAI = "https://api.openai.com/v1"
_GEMINI = "https://generativelanguage.googleapis.com/v1beta/openai/"
_OPENROUTER = "https://openrouter.ai/api/v1"


def _gpt5(name: str, effort: str) -> LvlmProfile:
    # GPT-5: max_completion_tokens (reasoning tokens count against it: too small a cap returns empty
    # content with finish_reason "length"), reasoning_effort, and no temperature (fixed at 1).
    return LvlmProfile(
        name=name,
        base_url=_OPENAI,
        model=name,
        api_key_env="OPENAI_API_KEY",
        max_tokens=None,
        max_completion_tokens=6000,
        reasoning_effort=effort,  # type: ignore[arg-type]
        temperature=None,
    )


BUILTIN_PROFILES: Mapping[str, LvlmProfile] = {
    p.name: p
    for p in (
        _gpt5("gpt-5", "low"),
        _gpt5("gpt-5-mini", "low"),
        _gpt5("gpt-5-nano", "low"),
        # Gemini's OpenAI-compatible endpoint rejects additionalProperties and $schema: relaxed schema.
        LvlmProfile(
            name="gemini-2.5-flash",
            base_url=_GEMINI,
            model="gemini-2.5-flash",
            api_key_env="GEMINI_API_KEY",
            schema="relaxed",
            max_tokens=4096,
        ),
        LvlmProfile(
            name="openrouter-gemini-2.5-flash",
            base_url=_OPENROUTER,
            model="google/gemini-2.5-flash",
            api_key_env="OPENROUTER_API_KEY",
            schema="relaxed",
            max_tokens=4096,
            headers={"HTTP-Referer": "https://github.com/landfall-drone/landfall", "X-Title": "Landfall"},
            # route only to providers that honour response_format
            extra_body={"provider": {"require_parameters": True}},
        ),
        # Edge models on the companion or a nearby box. vLLM: --limit-mm-per-prompt '{"image":5}' for 5
        # crops; it honours json_schema. Ollama may ignore a schema: the prompt and the parser carry it.
        LvlmProfile(
            name="vllm-qwen2.5-vl",
            base_url="http://localhost:8000/v1",
            model="Qwen/Qwen2.5-VL-7B-Instruct",
            attempt_timeout_s=60.0,
        ),
        LvlmProfile(
            name="vllm-internvl",
            base_url="http://localhost:8000/v1",
            model="OpenGVLab/InternVL3-8B",
            attempt_timeout_s=60.0,
        ),
        LvlmProfile(
            name="ollama-qwen2.5-vl",
            base_url="http://localhost:11434/v1",
            model="qwen2.5vl:7b",
            schema="relaxed",
            attempt_timeout_s=60.0,
        ),
    )
}


def resolve_profile(name: str, configured: Mapping[str, LvlmProfileConfig], option: str) -> LvlmProfile:
    """The profile called ``name``: a built-in with the config's fields laid over it, or the config's own."""
    base = BUILTIN_PROFILES.get(name)
    user = configured.get(name)
    if base is None and user is None:
        known = sorted({ONBOARD, *BUILTIN_PROFILES, *configured})
        raise ConfigError(option, f"unknown reasoner {name!r}; available: {', '.join(known)}")
    if user is None:
        assert base is not None
        return base
    fields: dict[str, Any] = {k: getattr(user, k) for k in user.model_fields_set}
    if "schema_variant" in fields:
        fields["schema"] = fields.pop("schema_variant")
    if fields.get("api_key_env") == "":
        fields["api_key_env"] = None
    if "max_completion_tokens" in fields:  # GPT-5 style: no max_tokens; no temperature unless given
        fields.setdefault("max_tokens", None)
        fields.setdefault("temperature", None)
    if base is None:
        missing = [k for k in ("base_url", "model") if k not in fields]
        if missing:
            raise ConfigError(f"reasoner.profiles.{name}", f"a new profile needs {' and '.join(missing)}")
        return LvlmProfile(name=name, **fields)
    return dataclasses.replace(base, **fields)


def api_keys(cfg: ReasonerConfig, env: Mapping[str, str]) -> list[str]:
    """The API keys (values) in ``env`` of every profile the config names or defines."""
    names = {*BUILTIN_PROFILES, *cfg.profiles}
    keys: list[str] = []
    for name in sorted(names):
        with contextlib.suppress(ConfigError):
            var = resolve_profile(name, cfg.profiles, "reasoner.profiles").api_key_env
            if var and env.get(var, "").strip():
                keys.append(env[var].strip())
    return keys


def secrets(cfg: CompanionConfig, env: Mapping[str, str]) -> list[str]:
    """Every secret a configuration gives the daemon (for the log's redaction): the signing key as hex
    in both cases, the broker password, the API keys of the reasoner's profiles."""
    out = [k for k in (cfg.mqtt_password(env),) if k]
    key = cfg.signing_key()
    if key is not None:
        out += [key.hex(), key.hex().upper()]
    return out + api_keys(cfg.reasoner, env)


def tier_names(cfg: ReasonerConfig, stage: str) -> list[str]:
    """The remote tiers of a stage in order (the onboard tier, always last, is not listed)."""
    fallbacks = cfg.rank_fallbacks if stage == "rank" else cfg.confirm_fallbacks
    names: list[str] = []
    for n in (cfg.name, *fallbacks):
        if n == ONBOARD:
            break
        if n not in names:
            names.append(n)
    return names


def build_cascade(
    cfg: ReasonerConfig,
    *,
    env: Mapping[str, str] | None = None,
    record: Callable[[str, dict[str, Any]], None] | None = None,
    client: httpx.AsyncClient | None = None,
) -> Cascade:
    """The cascade the config describes; unknown names are a :class:`ConfigError`. Tiers whose key is
    missing are kept (the key may be set later by a restart) but warned about: they answer
    ``not_configured`` and the next tier takes over at once."""
    import os

    environ = os.environ if env is None else env
    made: dict[str, Reasoner] = {}

    def tier(name: str, option: str) -> Reasoner:
        if name not in made:
            profile = resolve_profile(name, cfg.profiles, option)
            if profile.api_key_env and not environ.get(profile.api_key_env):
                _log.warning("reasoner %s: %s is not set: the tier will hand over", name, profile.api_key_env)
            made[name] = LvlmReasoner(profile, client=client, env=environ)
        return made[name]

    stages: dict[str, list[Reasoner]] = {}
    for stage in ("rank", "confirm"):
        tiers = [
            tier(n, "reasoner.name" if n == cfg.name else f"reasoner.{stage}_fallbacks")
            for n in tier_names(cfg, stage)
        ]
        if cfg.hedge and tiers:
            tiers[0] = Hedged(tiers[0], tier(cfg.hedge, "reasoner.hedge"), cfg.hedge_after_s)
        stages[stage] = tiers
    params = CascadeParams(
        rank_deadline_s=cfg.rank_deadline_s,
        confirm_deadline_s=cfg.confirm_deadline_s,
        critical_deadline_factor=cfg.critical_deadline_factor,
        override_after=cfg.override_lone_no_after,
    )
    try:  # loads the model now: a missing or corrupt file fails start-up, naming it
        net = LandNet.load(cfg.onboard_model) if cfg.onboard_judge == "landnet" else None
        confirm = ConfirmParams(
            open_ground_area_m2=cfg.open_ground_area_m2, open_ground_edge_m=cfg.open_ground_edge_m
        )
        onboard = OnboardReasoner(judge=cfg.onboard_judge, landnet=net, confirm=confirm)
    except LandNetError as exc:
        raise ConfigError(
            f"reasoner.onboard_judge = {cfg.onboard_judge!r}, onboard_model = {cfg.onboard_model!r}", str(exc)
        ) from exc
    return Cascade(stages["rank"], stages["confirm"], onboard, params, record)
