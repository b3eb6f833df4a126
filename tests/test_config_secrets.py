"""The companion's secrets in its configuration (companion.config): the MAVLink signing key from the
environment (never from the file unwarned), bad keys named without echoing them, and no secret in a
repr, a dump or the log. The rest of the configuration: tests/test_config.py."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import pytest

from companion.config import load_config
from companion.reasoning.tiers import secrets as tier_secrets
from tests.test_config import KEY_HEX, KEY_HEX_2, error_of, write


@pytest.fixture
def in_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Work in tmp_path so a relative Path("companion.toml") reads as the user typed it."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


# --- the signing key ---------------------------------------------------------------------------------


def test_signing_key_from_default_env_variable() -> None:
    cfg = load_config(None, {"LANDFALL_SIGNING_KEY": KEY_HEX.upper() + "\n"}, {})
    assert cfg.signing_key() == bytes.fromhex(KEY_HEX)
    assert len(cfg.signing_key() or b"") == 32


def test_signing_key_env_beats_file_and_file_key_is_warned(
    in_tmp: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = write(Path("companion.toml"), f'[mavlink]\nsigning_key = "{KEY_HEX}"\n')
    assert load_config(path, {"LANDFALL_SIGNING_KEY": KEY_HEX_2}, {}).signing_key() == bytes.fromhex(
        KEY_HEX_2
    )
    assert "discouraged" not in caplog.text
    with caplog.at_level(logging.WARNING, logger="companion.config"):
        cfg = load_config(path, {}, {})
    assert cfg.signing_key() == bytes.fromhex(KEY_HEX)
    assert "companion.toml: mavlink.signing_key: a key in the file is discouraged" in caplog.text
    assert KEY_HEX not in caplog.text


def test_signing_key_env_name_is_configurable_and_exempt(in_tmp: Path) -> None:
    # The variable starts like an option of [mavlink] but is named by signing_key_env, so it is no typo.
    path = write(Path("companion.toml"), '[mavlink]\nsigning_key_env = "LANDFALL_MAVLINK_KEY"\n')
    cfg = load_config(path, {"LANDFALL_MAVLINK_KEY": KEY_HEX, "LANDFALL_SIGNING_KEY": KEY_HEX_2}, {})
    assert cfg.signing_key() == bytes.fromhex(KEY_HEX)


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        (KEY_HEX[:-2], "must be 64 hex digits (a 32-byte key); got 62 hex digits"),
        (KEY_HEX + "00", "must be 64 hex digits (a 32-byte key); got 66 hex digits"),
        (KEY_HEX[:-1] + "g", "must be 64 hex digits (a 32-byte key); it has non-hex characters"),
        ("", "is empty: set 64 hex digits (a 32-byte key), or unset it to run unsigned"),
    ],
)
def test_signing_key_bad_value_is_named_and_not_echoed(value: str, problem: str) -> None:
    err = error_of(None, {"LANDFALL_SIGNING_KEY": value})
    assert (err.option, err.problem) == ("LANDFALL_SIGNING_KEY", problem)
    if value:
        assert value not in str(err)
        assert value[:16] not in str(err)
    assert err.__cause__ is None
    assert err.__suppress_context__ is True


def test_signing_key_bad_value_in_file_is_not_echoed(in_tmp: Path) -> None:
    bad = "ab" * 31
    err = error_of(write(Path("companion.toml"), f'[mavlink]\nsigning_key = "{bad}"\n'))
    assert err.option == "companion.toml: mavlink.signing_key"
    assert bad not in str(err)


def test_signing_key_never_in_repr_str_or_dumps(caplog: pytest.LogCaptureFixture) -> None:
    cfg = load_config(None, {"LANDFALL_SIGNING_KEY": KEY_HEX}, {})
    logging.getLogger("test").warning("config %s / %r", cfg, cfg.mavlink)
    for text in (
        repr(cfg),
        str(cfg),
        repr(cfg.mavlink),
        str(cfg.mavlink),
        cfg.model_dump_json(),
        caplog.text,
    ):
        assert KEY_HEX not in text
        assert KEY_HEX.upper() not in text
    assert "**********" in repr(cfg.mavlink)


def test_the_log_redacts_every_secret_the_config_gives(
    in_tmp: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The second line of defence: text from outside (an error message quoting a key, a traceback)
    that holds a secret is masked by the handlers' filter before it is written."""
    from companion.redact import MASK, redact_logs

    env = {
        "LANDFALL_SIGNING_KEY": KEY_HEX,
        "OPENAI_API_KEY": "sk-openai-0123456789",
        "MY_EDGE_KEY": "edge-key-abcdefgh",
        "LANDFALL_MQTT_PASSWORD": "broker-pass-1234",
        "UNRELATED": "not-a-secret-value",
    }
    path = Path("companion.toml")
    path.write_text(
        '[reasoner.profiles.edge]\nbase_url = "http://127.0.0.1:1/v1"\nmodel = "m"\n'
        'api_key_env = "MY_EDGE_KEY"\n[mqtt]\npassword_env = "LANDFALL_MQTT_PASSWORD"\n'
    )
    secrets = tier_secrets(load_config(path, env, {}), env)
    assert set(secrets) == {
        KEY_HEX, KEY_HEX.upper(), "sk-openai-0123456789", "edge-key-abcdefgh", "broker-pass-1234"
    }  # fmt: skip
    logger = logging.getLogger("test.redact")
    logger.propagate = False
    handler = logging.StreamHandler(sys.stderr)
    logger.addHandler(handler)
    try:
        redact_logs(secrets, logger)
        logger.warning("provider said: Incorrect API key provided: %s", "sk-openai-0123456789")
        logger.warning("key %s in upper case %s", KEY_HEX, KEY_HEX.upper())
        try:
            raise RuntimeError("auth failed for edge-key-abcdefgh")
        except RuntimeError:
            logger.exception("the tier failed")
        logger.warning("left alone: %s", "not-a-secret-value")
    finally:
        logger.removeHandler(handler)
    err = capsys.readouterr().err
    for secret in secrets:
        assert secret not in err
    assert err.count(MASK) == 5  # 1 + 2 + the traceback's source line and its message
    assert "RuntimeError: auth failed for [redacted]" in err
    assert "left alone: not-a-secret-value" in err
