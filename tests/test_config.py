"""companion.config and its schema (companion.config_schema): defaults, precedence, errors naming the
option, the shipped TOML, the reasoner's tiers. The signing key and the other secrets:
tests/test_config_secrets.py."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest
from pydantic import ValidationError

from companion.config import ConfigError, env_var_name, load_config
from companion.config_schema import CompanionConfig, RoundsByCriticality, SearchWindow
from landfall_link.mavlink import URL_FORMS

REPO = Path(__file__).resolve().parents[1]
KEY_HEX = "0123456789abcdef" * 4
KEY_HEX_2 = "fedcba9876543210" * 4


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.fixture
def in_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Work in tmp_path so a relative Path("companion.toml") reads as the user typed it."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def error_of(path: Path | None = None, env: dict[str, str] | None = None, **overrides: object) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        load_config(path, env or {}, {k.replace("__", "."): v for k, v in overrides.items()})
    return info.value


# --- defaults and precedence -------------------------------------------------------------------------


def test_load_config_defaults_match_the_brief() -> None:
    cfg = load_config(None, {}, {})
    assert cfg == CompanionConfig()
    assert cfg.mavlink.url == "udp:14550"
    assert cfg.mavlink.component_id == 191
    assert cfg.mavlink.vehicle_system_id == 0
    assert cfg.mavlink.signing_key_env == "LANDFALL_SIGNING_KEY"
    assert cfg.mavlink.signing_key is None
    assert cfg.mavlink.heartbeat_hz == 1.0
    assert (cfg.sensors.endpoint, cfg.sensors.frame_timeout_s, cfg.sensors.max_frame_age_s) == (
        "127.0.0.1:5601",
        10.0,
        2.0,
    )
    r = cfg.recovery
    assert r.max_rounds == 10
    assert r.rounds_by_criticality == RoundsByCriticality(low=10, high=6, critical=3)
    assert (r.descent_fraction, r.final_land_m, r.arrival_tolerance_m, r.arrival_speed_m_s) == (
        0.8,
        5.0,
        0.5,
        0.3,
    )
    assert (r.move_timeout_s, r.move_timeout_s_per_m, r.explore_climb_m, r.explore_max_alt_m) == (
        60.0,
        0.5,
        15.0,
        90.0,
    )
    pc = cfg.perception
    assert (pc.depth, pc.depth_model, pc.cell_px, pc.window_cells) == ("lidar", None, 4, 5)
    assert (pc.max_slope_deg, pc.max_roughness_m, pc.min_area_m2, pc.edge_margin_m, pc.max_candidates) == (
        8.0,
        0.06,
        30.0,
        2.0,
        5,
    )
    a = cfg.alarms
    assert (a.watch_battery, a.battery_critical_pct, a.watch_failsafe_text, a.watch_gps) == (
        True,
        15.0,
        True,
        True,
    )
    assert a.accept_from_system_ids == ()
    assert (cfg.reasoner.name, cfg.reasoner.rank_deadline_s, cfg.reasoner.confirm_deadline_s) == (
        "onboard",
        10.0,
        6.0,
    )
    assert (cfg.record.dir, cfg.record.max_mb) == (None, 500)
    assert cfg.log.level == "INFO"
    assert cfg.signing_key() is None


def test_load_config_precedence_file_then_env_then_flags(in_tmp: Path) -> None:
    path = write(
        Path("companion.toml"),
        """
        [recovery]
        max_rounds = 7
        final_land_m = 4.0
        [sensors]
        endpoint = "10.0.0.1:1000"
        frame_timeout_s = 3.0
        [reasoner]
        name = "from-file"
        """,
    )
    env = {
        "LANDFALL_RECOVERY_MAX_ROUNDS": "6",
        "LANDFALL_SENSORS_ENDPOINT": "10.0.0.2:2000",
        "LANDFALL_REASONER_NAME": "from-env",
    }
    overrides = {"sensors.endpoint": "10.0.0.3:3000", "mavlink.url": None, "record.dir": Path("rec")}
    cfg = load_config(path, env, overrides)
    assert cfg.recovery.final_land_m == 4.0  # file only
    assert cfg.sensors.frame_timeout_s == 3.0  # file only
    assert cfg.recovery.max_rounds == 6  # env beats file
    assert cfg.reasoner.name == "from-env"  # env beats file
    assert cfg.sensors.endpoint == "10.0.0.3:3000"  # flag beats env and file
    assert cfg.mavlink.url == "udp:14550"  # a None override means "flag not given"
    assert cfg.record.dir == Path("rec")


def test_load_config_env_sub_table_replaces_only_given_keys(in_tmp: Path) -> None:
    path = write(
        Path("companion.toml"), "[recovery.rounds_by_criticality]\nlow = 9\nhigh = 5\ncritical = 4\n"
    )
    cfg = load_config(path, {"LANDFALL_RECOVERY_ROUNDS_BY_CRITICALITY": "critical=1"}, {})
    assert cfg.recovery.rounds_by_criticality == RoundsByCriticality(low=9, high=5, critical=1)


def test_load_config_env_text_parses_to_field_types() -> None:
    env = {
        "LANDFALL_ALARMS_WATCH_GPS": "off",
        "LANDFALL_ALARMS_WATCH_BATTERY": "Yes",
        "LANDFALL_ALARMS_BATTERY_CRITICAL_PCT": "20.5",
        "LANDFALL_ALARMS_ACCEPT_FROM_SYSTEM_IDS": "1, 255",
        "LANDFALL_MAVLINK_COMPONENT_ID": "190",
        "LANDFALL_RECORD_DIR": "/var/lib/landfall",
        "LANDFALL_RECORD_MAX_MB": "64",
        "LANDFALL_LOG_LEVEL": "debug",
        "LANDFALL_OTHER_THING": "ignored: not a section",
        "LANDFALL_SIGNING_KEY_FILE": "ignored: SIGNING is not a section",
    }
    cfg = load_config(None, env, {})
    assert cfg.alarms.watch_gps is False
    assert cfg.alarms.watch_battery is True
    assert cfg.alarms.battery_critical_pct == 20.5
    assert cfg.alarms.accept_from_system_ids == (1, 255)
    assert cfg.mavlink.component_id == 190
    assert cfg.record.dir == Path("/var/lib/landfall")
    assert cfg.record.max_mb == 64
    assert cfg.log.level == "DEBUG"


def test_load_config_empty_env_for_optional_means_none(in_tmp: Path) -> None:
    path = write(Path("companion.toml"), '[record]\ndir = "/data/rec"\n')
    assert load_config(path, {"LANDFALL_RECORD_DIR": ""}, {}).record.dir is None
    assert (
        load_config(path, {"LANDFALL_ALARMS_ACCEPT_FROM_SYSTEM_IDS": ""}, {}).alarms.accept_from_system_ids
        == ()
    )


def test_load_config_flag_text_is_parsed_for_non_string_options() -> None:
    cfg = load_config(None, {}, {"recovery.max_rounds": "4", "record.dir": "/tmp/rec"})
    assert cfg.recovery.max_rounds == 4
    assert cfg.record.dir == Path("/tmp/rec")


def test_companion_config_is_frozen() -> None:
    cfg = load_config(None, {}, {})
    with pytest.raises(ValidationError):
        cfg.recovery.max_rounds = 3


def test_rounds_for_caps_by_max_rounds() -> None:
    assert load_config(None, {}, {}).rounds_for("critical") == 3
    assert load_config(None, {}, {}).rounds_for("low") == 10
    assert load_config(None, {"LANDFALL_RECOVERY_MAX_ROUNDS": "2"}, {}).rounds_for("high") == 2


def test_a_moves_allowance_grows_with_its_distance_as_configured() -> None:
    from companion.cli import params_from

    cfg = load_config(None, {"LANDFALL_RECOVERY_MOVE_TIMEOUT_S_PER_M": "0.25"}, {})
    p = params_from(cfg)
    assert p.move_timeout(0.0) == 60.0
    assert p.move_timeout(40.0) == 70.0
    assert params_from(load_config(None, {}, {})).move_timeout(40.0) == 80.0  # 0.5 s a metre


def test_env_var_name_upper_cases_section_and_key() -> None:
    assert env_var_name("recovery.max_rounds") == "LANDFALL_RECOVERY_MAX_ROUNDS"


# --- errors name the option --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ("[recovery]\nmax_rounds = 0", "companion.toml: recovery.max_rounds: must be >= 1 (got 0)"),
        (
            "[recovery]\nmax_rounds = '10'",
            "companion.toml: recovery.max_rounds: must be an integer (got '10')",
        ),
        (
            "[recovery]\ndescent_fraction = 1.0",
            "companion.toml: recovery.descent_fraction: must be < 1 (got 1.0)",
        ),
        (
            "[recovery]\ndescent_fraction = 0",
            "companion.toml: recovery.descent_fraction: must be > 0 (got 0)",
        ),
        (
            "[recovery]\nfinal_land_m = nan",
            "companion.toml: recovery.final_land_m: must be a finite number (got nan)",
        ),
        ("[alarms]\nwatch_gps = 1", "companion.toml: alarms.watch_gps: must be true or false (got 1)"),
        (
            "[alarms]\nbattery_critical_pct = 101",
            "companion.toml: alarms.battery_critical_pct: must be <= 100 (got 101)",
        ),
        (
            "[alarms]\naccept_from_system_ids = [1, 0]",
            "companion.toml: alarms.accept_from_system_ids[1]: must be >= 1 (got 0)",
        ),
        ("[mavlink]\ncomponent_id = 256", "companion.toml: mavlink.component_id: must be <= 255 (got 256)"),
        (
            "[mavlink]\nurl = 'tcp:5760'",
            "companion.toml: mavlink.url: a tcp link needs HOST:PORT, e.g. tcp:127.0.0.1:5760 "
            "(got 'tcp:5760')",
        ),
        (
            "[mavlink]\nsigning_key_env = 'A B'",
            "companion.toml: mavlink.signing_key_env: must be an environment",
        ),
        ("[sensors]\nendpoint = 'localhost'", "companion.toml: sensors.endpoint: must be HOST:PORT"),
        ("[reasoner]\nname = ''", "companion.toml: reasoner.name: must not be empty (got '')"),
        ("[record]\nmax_mb = 0", "companion.toml: record.max_mb: must be >= 1 (got 0)"),
        (
            "[log]\nlevel = 'LOUD'",
            "companion.toml: log.level: must be one of DEBUG, INFO, WARNING, ERROR, CRITICAL",
        ),
        (
            "[recovery.rounds_by_criticality]\ncritical = 0",
            "companion.toml: recovery.rounds_by_criticality.critical",
        ),
        (
            "[recovery.rounds_by_criticality]\nlow = 2",
            "companion.toml: recovery.rounds_by_criticality: must not grow with criticality",
        ),
        ("recovery = 5", "companion.toml: recovery: must be a table ([recovery]), got 5"),
        (
            "[recovery]\nmax_round = 3",
            "companion.toml: recovery.max_round: unknown option (allowed: max_rounds, ",
        ),
        (
            "[recovery.rounds_by_criticality]\nmedium = 3",
            "companion.toml: recovery.rounds_by_criticality.medium: "
            "unknown option (allowed: low, high, critical)",
        ),
        (
            "[recoverry]\nmax_rounds = 3",
            "companion.toml: recoverry: unknown section (allowed: mavlink, sensors",
        ),
        ("recovery = [", "companion.toml: invalid TOML"),
        (
            "[reasoner]\nonboard_judge = 'net'",
            "companion.toml: reasoner.onboard_judge: Input should be 'cues' or 'landnet' (got 'net')",
        ),
    ],
)
def test_load_config_file_error_names_option(in_tmp: Path, toml: str, message: str) -> None:
    err = error_of(write(Path("companion.toml"), toml))
    assert str(err).startswith(message)
    assert str(err) == f"{err.option}: {err.problem}"
    assert err.option.startswith("companion.toml")
    assert isinstance(err, ValueError)


def test_load_config_unknown_file_option_lists_all_allowed(in_tmp: Path) -> None:
    err = error_of(write(Path("companion.toml"), "[log]\nlevels = 'INFO'"))
    assert err.option == "companion.toml: log.levels"
    assert err.problem == "unknown option (allowed: level)"


def test_a_config_file_that_is_not_utf8_is_a_config_error(in_tmp: Path) -> None:
    """Found by atheris: a Latin-1 file used to escape as a UnicodeDecodeError."""
    path = Path("companion.toml")
    path.write_bytes("[recovery]\n# \u00e9t\u00e9\nmax_rounds = 3\n".encode("latin-1"))
    err = error_of(path)
    assert err.option == "companion.toml"
    assert err.problem == "not UTF-8 text: byte 13 is 0xe9"


def test_load_config_missing_file_names_the_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.toml"
    err = error_of(missing)
    assert err.option == str(missing)
    assert "cannot read the file" in err.problem


@pytest.mark.parametrize(
    ("env", "message"),
    [
        (
            {"LANDFALL_RECOVERY_MAX_ROUNDS": "ten"},
            "LANDFALL_RECOVERY_MAX_ROUNDS: must be an integer (got 'ten')",
        ),
        ({"LANDFALL_RECOVERY_MAX_ROUNDS": "0"}, "LANDFALL_RECOVERY_MAX_ROUNDS: must be >= 1 (got 0)"),
        (
            {"LANDFALL_RECOVERY_MAX_ROUNDS": "2.5"},
            "LANDFALL_RECOVERY_MAX_ROUNDS: must be an integer (got '2.5')",
        ),
        (
            {"LANDFALL_ALARMS_WATCH_GPS": "maybe"},
            "LANDFALL_ALARMS_WATCH_GPS: must be true or false (got 'maybe')",
        ),
        (
            {"LANDFALL_SENSORS_FRAME_TIMEOUT_S": "fast"},
            "LANDFALL_SENSORS_FRAME_TIMEOUT_S: must be a number (got 'fast')",
        ),
        (
            {"LANDFALL_SENSORS_FRAME_TIMEOUT_S": "-1"},
            "LANDFALL_SENSORS_FRAME_TIMEOUT_S: must be > 0 (got -1.0)",
        ),
        (
            {"LANDFALL_SENSORS_FRAME_TIMEOUT_S": "inf"},
            "LANDFALL_SENSORS_FRAME_TIMEOUT_S: must be a finite number",
        ),
        (
            {"LANDFALL_ALARMS_ACCEPT_FROM_SYSTEM_IDS": "1,x"},
            "LANDFALL_ALARMS_ACCEPT_FROM_SYSTEM_IDS: must be a comma-separated list of integers (got '1,x')",
        ),
        (
            {"LANDFALL_ALARMS_ACCEPT_FROM_SYSTEM_IDS": "1,300"},
            "LANDFALL_ALARMS_ACCEPT_FROM_SYSTEM_IDS[1]: must be <= 255 (got 300)",
        ),
        (
            {"LANDFALL_RECOVERY_ROUNDS_BY_CRITICALITY": "critical=0"},
            "LANDFALL_RECOVERY_ROUNDS_BY_CRITICALITY (critical): must be >= 1 (got 0)",
        ),
        (
            {"LANDFALL_RECOVERY_ROUNDS_BY_CRITICALITY": "crit=1"},
            "LANDFALL_RECOVERY_ROUNDS_BY_CRITICALITY: must be a comma-separated list of "
            "low=..., high=..., critical=... (got 'crit=1')",
        ),
        (
            {"LANDFALL_RECOVERY_ROUNDS_BY_CRITICALITY": "low=1"},
            "LANDFALL_RECOVERY_ROUNDS_BY_CRITICALITY: must not grow with criticality",
        ),
        (
            {"LANDFALL_RECOVERY_MAX_ROUND": "3"},
            "LANDFALL_RECOVERY_MAX_ROUND: unknown option (allowed: LANDFALL_RECOVERY_MAX_ROUNDS, ",
        ),
        ({"LANDFALL_SENSORS_ENDPOINT": "host:0"}, "LANDFALL_SENSORS_ENDPOINT: must be HOST:PORT"),
        ({"LANDFALL_LOG_LEVEL": "chatty"}, "LANDFALL_LOG_LEVEL: must be one of"),
    ],
)
def test_load_config_env_error_names_variable(env: dict[str, str], message: str) -> None:
    err = error_of(None, env)
    assert str(err).startswith(message)
    assert err.option == message.split(":")[0]


def test_load_config_env_error_beats_valid_file(in_tmp: Path) -> None:
    path = write(Path("companion.toml"), "[recovery]\nmax_rounds = 4\n")
    err = error_of(path, {"LANDFALL_RECOVERY_MAX_ROUNDS": "-2"})
    assert err.option == "LANDFALL_RECOVERY_MAX_ROUNDS"
    assert err.problem == "must be >= 1 (got -2)"


@pytest.mark.parametrize(
    ("overrides", "option", "problem"),
    [
        (
            {"sensors__endpoint": "localhost"},
            "--sensors",
            "must be HOST:PORT with a port in 1..65535 (got 'localhost')",
        ),
        (
            {"sensors__endpoint": "h:70000"},
            "--sensors",
            "must be HOST:PORT with a port in 1..65535 (got 'h:70000')",
        ),
        (
            {"mavlink__url": "14550"},
            "--mavlink",
            f"unknown form; expected {URL_FORMS} (got '14550')",
        ),
        ({"mavlink__url": "udp:0"}, "--mavlink", "port must be in 1..65535 (got 'udp:0')"),
        ({"reasoner__name": "two words"}, "--reasoner", "must be one word (no spaces) (got 'two words')"),
        ({"record__dir": 5}, "--record", "must be a path (a string) (got 5)"),
        (
            {"log__level": "loud"},
            "--log-level",
            "must be one of DEBUG, INFO, WARNING, ERROR, CRITICAL (got 'loud')",
        ),
        ({"recovery__max_rounds": "x"}, "override recovery.max_rounds", "must be an integer (got 'x')"),
    ],
)
def test_load_config_flag_error_names_flag(overrides: dict[str, object], option: str, problem: str) -> None:
    err = error_of(None, None, **overrides)
    assert (err.option, err.problem) == (option, problem)


def test_load_config_unknown_override_lists_options() -> None:
    err = error_of(None, None, sensor__endpoint="h:1")
    assert err.option == "override sensor.endpoint"
    assert err.problem.startswith("unknown option (allowed: mavlink.url, mavlink.component_id,")
    assert "sensors.endpoint" in err.problem


# --- the shipped example -----------------------------------------------------------------------------


def test_deploy_companion_toml_loads_to_defaults() -> None:
    path = REPO / "deploy" / "companion.toml"
    assert load_config(path, {}, {}) == CompanionConfig()


def test_deploy_companion_toml_lists_every_option_with_a_comment() -> None:
    path = REPO / "deploy" / "companion.toml"
    text = path.read_text()
    data = tomllib.loads(text)
    present: set[str] = set()
    for section, table in data.items():
        for key, value in table.items():
            if isinstance(value, dict):
                present.update(f"{section}.{key}.{sub}" for sub in value)
            else:
                present.add(f"{section}.{key}")
    expected: set[str] = set()
    for section, field in CompanionConfig.model_fields.items():
        model = field.annotation
        assert isinstance(model, type)
        for key in model.model_fields:
            sub = model.model_fields[key].annotation
            if sub in (RoundsByCriticality, SearchWindow):
                assert isinstance(sub, type)
                expected.update(f"{section}.{key}.{k}" for k in sub.model_fields)
            else:
                expected.add(f"{section}.{key}")
    # The key itself is documented but commented out: keys belong in the environment. LVLM profiles are
    # optional tables, documented with a commented-out example.
    assert present == expected - {"mavlink.signing_key", "reasoner.profiles"}
    assert "# signing_key = " in text
    assert "# [reasoner.profiles." in text
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if "=" in line and not line.startswith("#"):
            assert lines[i - 1].startswith("#"), f"option without a comment above it: {line!r}"


# --- reasoner tiers and LVLM profiles ----------------------------------------------------------------


def test_reasoner_profiles_and_fallbacks_from_file_and_env(in_tmp: Path) -> None:
    from companion.reasoning.tiers import resolve_profile

    path = write(
        Path("companion.toml"),
        """
        [reasoner]
        name = "gpt-5-mini"
        [reasoner.profiles.gpt-5-mini]
        reasoning_effort = "minimal"
        [reasoner.profiles.edge]
        base_url = "http://10.0.0.2:8000/v1"
        model = "Qwen/Qwen2.5-VL-7B-Instruct"
        api_key_env = ""
        schema_variant = "none"
        """.replace("\n        ", "\n"),
    )
    cfg = load_config(path, {"LANDFALL_REASONER_RANK_FALLBACKS": "edge, onboard"}, {})
    assert cfg.reasoner.rank_fallbacks == ("edge", "onboard")
    mini = resolve_profile("gpt-5-mini", cfg.reasoner.profiles, "x")
    # only the given key changes over the built-in
    assert (mini.reasoning_effort, mini.max_completion_tokens, mini.api_key_env) == (
        "minimal",
        6000,
        "OPENAI_API_KEY",
    )
    edge = resolve_profile("edge", cfg.reasoner.profiles, "x")
    assert (edge.base_url, edge.api_key_env, edge.schema) == ("http://10.0.0.2:8000/v1", None, "none")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            '[reasoner.profiles.edge]\nbase_url = "http://x/v1"\nmodle = "m"',
            "companion.toml: reasoner.profiles.edge.modle: unknown option (allowed: base_url, model,",
        ),
        (
            '[reasoner.profiles.edge]\nbase_url = "ftp://x"',
            "companion.toml: reasoner.profiles.edge.base_url: ",
        ),
        (
            '[reasoner.profiles.edge]\nmodel = "m"\nreasoning_effort = "max"',
            "companion.toml: reasoner.profiles.edge.reasoning_effort: ",
        ),
        ('[reasoner]\ncontext = "pad25"', "companion.toml: reasoner.context: "),
        (
            "[reasoner]\ncritical_deadline_factor = 2.0",
            "companion.toml: reasoner.critical_deadline_factor: must be <= 1",
        ),
    ],
)
def test_reasoner_config_errors(in_tmp: Path, text: str, message: str) -> None:
    assert str(error_of(write(Path("companion.toml"), text))).startswith(message)


def test_a_new_profile_needs_base_url_and_model(in_tmp: Path) -> None:
    from companion.reasoning.tiers import resolve_profile

    cfg = load_config(write(Path("companion.toml"), '[reasoner.profiles.edge]\nmodel = "m"'), {}, {})
    with pytest.raises(ConfigError, match=r"reasoner\.profiles\.edge: a new profile needs base_url"):
        resolve_profile("edge", cfg.reasoner.profiles, "reasoner.name")


def test_reasoner_onboard_judge_from_file_and_env(in_tmp: Path) -> None:
    assert CompanionConfig().reasoner.onboard_judge == "landnet"
    path = write(Path("companion.toml"), '[reasoner]\nonboard_judge = "cues"\n')
    assert load_config(path, {}, {}).reasoner.onboard_judge == "cues"
    env = {"LANDFALL_REASONER_ONBOARD_JUDGE": "landnet"}
    assert load_config(path, env, {}).reasoner.onboard_judge == "landnet"


def test_reasoner_onboard_model_names_a_packaged_net_or_a_file_and_a_bad_one_fails_start_up(
    in_tmp: Path,
) -> None:
    import shutil

    from companion.reasoning.landnet import DEFAULT_MODEL, PACKAGED
    from companion.reasoning.tiers import build_cascade

    assert CompanionConfig().reasoner.onboard_model == "landnet-e"
    assert PACKAGED["landnet-e"] == DEFAULT_MODEL
    for name in PACKAGED:  # each packaged net by its name
        path = write(Path(f"{name}.toml"), f'[reasoner]\nonboard_model = "{name}"\n')
        packaged = build_cascade(load_config(path, {}, {}).reasoner).onboard.landnet
        assert packaged is not None
        assert packaged.name == name
    Path("nets").mkdir()
    light = PACKAGED["landnet-s"]  # one file and its sidecar (LandNet-E's whole read is a second file)
    shutil.copy(light, "nets/mine.onnx")
    meta = json.loads(light.with_suffix(".json").read_text()) | {"name": "mine"}
    Path("nets/mine.json").write_text(json.dumps(meta))
    path = write(Path("companion.toml"), '[reasoner]\nonboard_model = "nets/mine.onnx"\n')
    net = build_cascade(load_config(path, {}, {}).reasoner).onboard.landnet
    assert net is not None
    assert net.name == "mine"
    gone = write(Path("other.toml"), '[reasoner]\nonboard_model = "nets/gone.onnx"\n')
    with pytest.raises(ConfigError, match=r"onboard_model = 'nets/gone.onnx'.*gone\.onnx: model file not"):
        build_cascade(load_config(gone, {}, {}).reasoner)
