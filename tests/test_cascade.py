"""The tier cascade against a scripted local OpenAI-compatible server: every failure hands over to the
next tier (in the end the onboard one) within the stage deadline; hedging; confirmation arbitration
(geometric veto, the lone-"no" rule); companion-eval rank/confirm."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from companion.config import ConfigError
from companion.config_schema import ReasonerConfig
from companion.eval_cli import main as eval_main
from companion.perception.site_check import SiteCheck
from companion.reasoning.base import ConfirmRequest, RankRequest
from companion.reasoning.cascade import Cascade, CascadeParams, Hedged
from companion.reasoning.lvlm import LvlmProfile, LvlmReasoner
from companion.reasoning.onboard import OnboardReasoner
from companion.reasoning.tiers import build_cascade
from simbridge.geo import euler_to_quat
from simbridge.scenarios import load_scenario
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass as C
from tests.lvlm_server import Reply, ScriptedServer, answer, completion
from tests.views import centre_window, close_up, share, site_cut

GOOD_RANK = answer({"explanation": "candidate 2 is a clear roof", "ranking": [2, 0, 1]})
YES = answer({"explanation": "clear gravel, nothing near the centre", "decision": 1})
NO = answer({"explanation": "birds on the roof", "decision": 0})
CLEAR = SiteCheck(240, 22.0, 0.01, 0.05, 9.0, ())
OBSTACLE = SiteCheck(240, 22.0, 0.01, 1.4, 9.0, ("object 1.4 m tall within 2 m",))


@pytest.fixture
def server() -> Iterator[ScriptedServer]:
    s = ScriptedServer()
    yield s
    s.close()


@pytest.fixture(scope="module")
def roofs() -> dict[str, np.ndarray]:
    """Close-ups rendered by simbridge, checked against its ground truth: the clear gravel roof and
    the cluttered one of scenario1, from 40 m above each."""
    world = load_scenario("scenario1", 0).terrain
    out = {}
    for name, (n, e, height) in {"clear": (0.0, -27.0, 22.0), "cluttered": (2.0, 24.0, 18.0)}.items():
        frame = world.camera_frame(  # type: ignore[attr-defined]
            (n, e, -(height + 40.0)), euler_to_quat(0.0, 0.0, 0.0), 0.0, "clear", np.random.default_rng(1)
        )
        sl = np.s_[170:370, 380:580]
        cls = frame.hit_class[sl]
        if name == "clear":
            assert (cls == C.ROOF_FLAT).mean() > 0.95
        else:
            assert (cls == C.ROOF_CLUTTER).mean() > 0.1
        out[name] = np.ascontiguousarray(frame.rgb[sl])
    return out


def lvlm(server: ScriptedServer, model: str, **kw: Any) -> LvlmReasoner:
    return LvlmReasoner(LvlmProfile(f"remote-{model}", server.base_url, model, **kw), env={})


def crops(n: int = 3) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(7)
    return tuple(rng.integers(90, 110, (120, 160, 3), dtype=np.uint8) for _ in range(n))


class Log:
    def __init__(self) -> None:
        self.events: list[dict[str, Any]] = []

    def __call__(self, kind: str, fields: dict[str, Any]) -> None:
        assert kind == "exchange"
        self.events.append(fields)


def cascade(tiers: list[Any], log: Log | None = None, **params: Any) -> Cascade:
    p = CascadeParams(**{"rank_deadline_s": 2.0, "confirm_deadline_s": 2.0, **params})
    return Cascade(tiers, tiers, OnboardReasoner(), p, log)


# ------------------------------------------------------------------------------------------ rank
FAILURES = [
    ("slow", Reply(body=GOOD_RANK.body, delay_s=10.0), "deadline"),
    (
        "ratelimited",
        Reply(429, {"error": {"message": "slow down"}}, headers={"Retry-After": "60"}),
        "rate_limited",
    ),
    ("down", Reply(500, {"error": {"message": "boom"}}), "http"),
    ("errorbody", Reply(body={"error": {"message": "provider overloaded"}}), "error_body"),
    ("empty", Reply(body=completion("")), "empty"),
    ("capped", Reply(body=completion(None, finish="length")), "truncated"),
    ("refusal", Reply(body=completion(None, refusal="I cannot assist with that.")), "refusal"),
    ("malformed", Reply(body=completion("I would go with the roof.")), "malformed"),
    ("truncated", Reply(body=completion('{"explanation": "the first site is')), "truncated"),
    ("outofrange", answer({"explanation": "x", "ranking": [3, 0, 1]}), "invalid_indices"),
    ("repeated", answer({"explanation": "x", "ranking": [0, 0, 1]}), "invalid_indices"),
]


@pytest.mark.parametrize(("model", "reply", "kind"), FAILURES, ids=[f[0] for f in FAILURES])
async def test_every_failure_hands_over_to_onboard_within_the_deadline(
    server: ScriptedServer, model: str, reply: Reply, kind: str
) -> None:
    server.script(model, reply)
    log = Log()
    c = cascade([lvlm(server, model)], log)
    t0 = time.monotonic()
    ranking = await c.rank(RankRequest(crops()))
    elapsed = time.monotonic() - t0
    await c.aclose()
    assert ranking.tier == "onboard"
    assert sorted(ranking.order) == [0, 1, 2]
    assert elapsed <= 2.0 + 0.3  # the stage deadline, with scheduling slack
    assert ranking.latency_s == pytest.approx(elapsed, abs=0.05)
    first, last = log.events
    assert first["tier"] == f"remote-{model}"
    assert first["error"]["kind"] == kind
    assert last["tier"] == "onboard"
    assert "parsed" in last


async def test_unreachable_and_keyless_tiers_hand_over() -> None:
    s = ScriptedServer()
    url = s.base_url
    s.close()
    log = Log()
    gone = LvlmReasoner(LvlmProfile("gone", url, "m", max_attempts=1), env={})
    nokey = LvlmReasoner(LvlmProfile("nokey", url, "m", api_key_env="NO_SUCH_KEY"), env={})
    c = cascade([nokey, gone], log)
    ranking = await c.rank(RankRequest(crops()))
    await c.aclose()
    assert ranking.tier == "onboard"
    assert [e.get("error", {}).get("kind") for e in log.events] == ["not_configured", "unreachable", None]


async def test_the_first_valid_answer_wins(server: ScriptedServer) -> None:
    server.script("bad", Reply(body=completion("no idea")))
    server.script("good", GOOD_RANK)
    server.script("never", GOOD_RANK)
    log = Log()
    c = cascade([lvlm(server, "bad"), lvlm(server, "good"), lvlm(server, "never")], log)
    ranking = await c.rank(RankRequest(crops()))
    await c.aclose()
    assert (ranking.tier, ranking.order) == ("remote-good", (2, 0, 1))
    assert [e["tier"] for e in log.events] == ["remote-bad", "remote-good"]
    assert server.seen("never") == []
    # the flight record gets the prompt, the image references and the raw answer
    transcript = log.events[1]["transcript"]
    assert any("prompt" in t and len(t["images"]) == 3 for t in transcript)
    assert any(t.get("raw") and "ranking" in t["raw"] for t in transcript)


async def test_a_critical_alarm_halves_the_deadline(server: ScriptedServer) -> None:
    server.script("slow", Reply(body=GOOD_RANK.body, delay_s=10.0))
    c = cascade([lvlm(server, "slow")], rank_deadline_s=2.0)
    assert c.deadline_s("rank", critical=True) == 1.0
    t0 = time.monotonic()
    ranking = await c.rank(RankRequest(crops(), critical=True))
    elapsed = time.monotonic() - t0
    await c.aclose()
    assert ranking.tier == "onboard"
    assert elapsed <= 1.0 + 0.3


async def test_hedge_answers_when_the_primary_is_slow(server: ScriptedServer) -> None:
    server.script("slow", Reply(body=GOOD_RANK.body, delay_s=10.0))
    server.script("quick", answer({"explanation": "candidate 1", "ranking": [1, 2, 0]}))
    c = cascade([Hedged(lvlm(server, "slow"), lvlm(server, "quick"), after_s=0.3)], rank_deadline_s=5.0)
    t0 = time.monotonic()
    ranking = await c.rank(RankRequest(crops()))
    elapsed = time.monotonic() - t0
    await c.aclose()
    assert (ranking.tier, ranking.order) == ("remote-quick", (1, 2, 0))
    assert elapsed < 5.0  # long before the stage deadline: the slow primary was not waited for
    first_quick = server.seen("quick")[0].t_monotonic
    assert first_quick - server.seen("slow")[0].t_monotonic >= 0.25  # started only after the delay


async def test_hedge_starts_at_once_when_the_primary_fails(server: ScriptedServer) -> None:
    server.script("broken", Reply(400, {"error": {"message": "bad request"}}))
    server.script("quick", GOOD_RANK)
    h = Hedged(lvlm(server, "broken"), lvlm(server, "quick"), after_s=3.0)
    t0 = time.monotonic()
    ranking = await h.rank(RankRequest(crops(), deadline=time.monotonic() + 5))
    await cascade([h]).aclose()
    assert ranking.tier == "remote-quick"
    assert time.monotonic() - t0 < 3.0


# ------------------------------------------------------------------------------------------ confirm
async def test_geometric_veto_overrides_a_yes(server: ScriptedServer, roofs: dict[str, np.ndarray]) -> None:
    server.script("m", YES)
    c = cascade([lvlm(server, "m")])
    d = await c.confirm(ConfirmRequest(roofs["clear"], OBSTACLE, site_ne_m=(0.0, -27.0)))
    await c.aclose()
    assert d.accept is False
    assert "geometric veto" in d.rationale
    assert "1.4 m" in d.rationale


async def test_a_yes_on_a_clear_site_descends(server: ScriptedServer, roofs: dict[str, np.ndarray]) -> None:
    server.script("m", YES)
    c = cascade([lvlm(server, "m")])
    d = await c.confirm(ConfirmRequest(roofs["clear"], CLEAR, site_ne_m=(0.0, -27.0)))
    await c.aclose()
    assert (d.accept, d.tier, d.contested) == (True, "remote-m", False)


async def test_a_yes_on_a_measured_roof_stands_over_the_onboard_doubts(
    server: ScriptedServer, city: LiveWorld
) -> None:
    """The clear gravel roof, measured 22 m up: the model's yes descends (a roof's doubts are the
    model's to weigh)."""
    server.script("m", YES)
    c = cascade([lvlm(server, "m")])
    frame, check = close_up(city, (0.0, -27.0), 22.0, 30.0)
    assert check.clear
    cut = site_cut(city, frame, 30.0)
    d = await c.confirm(ConfirmRequest(cut, check, site_ne_m=(0.0, -27.0), site_up_m=22.0))
    await c.aclose()
    assert (d.accept, d.tier) == (True, "remote-m")


@pytest.mark.parametrize(
    ("name", "ne", "up_m", "classes"),
    [
        ("empty street", (-40.0, 0.0), 0.0, (C.ROAD, C.CROSSWALK)),
        ("highway deck", (0.0, -80.0), 9.0, (C.HIGHWAY,)),
        ("harbour", (30.0, 100.0), -0.8, (C.WATER,)),
    ],
)
async def test_a_yes_on_a_road_or_water_is_outvoted_by_the_onboard_tier(
    server: ScriptedServer,
    city: LiveWorld,
    name: str,
    ne: tuple[float, float],
    up_m: float,
    classes: tuple[C, ...],
) -> None:
    """A model taken in by an empty road, a highway deck or flat water says yes; the LiDAR finds the
    rotor disc clear and level. The onboard tier's no there is binding (a street-level site, water, lane
    markings): the site is refused, not contested, and the record says whose veto it was."""
    server.script("m", answer({"explanation": "it says LAND HERE: land", "decision": 1}))
    c = cascade([lvlm(server, "m")])
    frame, _check = close_up(city, ne, up_m, 30.0)
    assert share(frame, centre_window(frame, 0.15), classes) > 0.5, name
    site_up = up_m if name == "highway deck" else 0.0  # what Surface ID measures above the surroundings
    cut = site_cut(city, frame, 30.0)
    d = await c.confirm(ConfirmRequest(cut, CLEAR, site_ne_m=ne, site_up_m=site_up))
    await c.aclose()
    assert (d.accept, d.contested, d.tier) == (False, False, "remote-m"), d.rationale
    assert d.rationale.startswith("onboard veto (rejected: "), d.rationale
    assert "LAND HERE" in d.rationale


async def test_lone_no_is_overridden_after_repeated_rounds(
    server: ScriptedServer, roofs: dict[str, np.ndarray]
) -> None:
    server.script("m", NO)
    c = cascade([lvlm(server, "m")], override_after=2)
    site = (0.0, -27.0)
    first = await c.confirm(ConfirmRequest(roofs["clear"], CLEAR, site_ne_m=site))
    assert (first.accept, first.contested) == (False, True)
    assert "birds" in first.rationale
    assert "1/2" in first.rationale
    elsewhere = await c.confirm(ConfirmRequest(roofs["clear"], CLEAR, site_ne_m=(40.0, 40.0)))
    assert (elsewhere.accept, elsewhere.contested) == (False, True)  # another site counts apart
    second = await c.confirm(ConfirmRequest(roofs["clear"], CLEAR, site_ne_m=(0.5, -26.5)))
    await c.aclose()
    assert second.accept is True
    assert "accepted over 2 lone no" in second.rationale


async def test_critical_alarm_overrides_a_lone_no_at_once(
    server: ScriptedServer, roofs: dict[str, np.ndarray]
) -> None:
    server.script("m", NO)
    c = cascade([lvlm(server, "m")])
    d = await c.confirm(ConfirmRequest(roofs["clear"], CLEAR, critical=True, site_ne_m=(0.0, -27.0)))
    await c.aclose()
    assert d.accept is True


async def test_a_no_backed_by_the_onboard_cues_is_never_overridden(
    server: ScriptedServer, roofs: dict[str, np.ndarray]
) -> None:
    server.script("m", NO)
    c = cascade([lvlm(server, "m")], override_after=1)
    for _ in range(3):
        d = await c.confirm(ConfirmRequest(roofs["cluttered"], CLEAR, site_ne_m=(2.0, 24.0)))
        assert (d.accept, d.contested) == (False, False)
        assert "onboard agrees" in d.rationale
    await c.aclose()


async def test_without_lidar_a_no_stands(server: ScriptedServer, roofs: dict[str, np.ndarray]) -> None:
    server.script("m", NO)
    c = cascade([lvlm(server, "m")], override_after=1)
    for _ in range(2):
        d = await c.confirm(ConfirmRequest(roofs["clear"], None, site_ne_m=(0.0, -27.0)))
        assert (d.accept, d.contested) == (False, False)
    await c.aclose()


async def test_confirm_failure_hands_over_to_onboard(
    server: ScriptedServer, roofs: dict[str, np.ndarray]
) -> None:
    server.script("m", Reply(503, {"error": {"message": "overloaded"}}))
    c = cascade([lvlm(server, "m", max_attempts=1)], confirm_deadline_s=1.0)
    clear = await c.confirm(ConfirmRequest(roofs["clear"], CLEAR, site_ne_m=(0.0, -27.0)))
    cluttered = await c.confirm(ConfirmRequest(roofs["cluttered"], CLEAR, site_ne_m=(2.0, 24.0)))
    await c.aclose()
    assert (clear.tier, clear.accept) == ("onboard", True)
    assert (cluttered.tier, cluttered.accept) == ("onboard", False)


# ------------------------------------------------------------------------------------------ config
def test_build_cascade_from_config_orders_tiers_per_stage() -> None:
    cfg = ReasonerConfig(
        name="gpt-5-mini",
        rank_fallbacks=("vllm-qwen2.5-vl", "onboard", "gpt-5"),
        confirm_fallbacks=(),
        hedge="gemini-2.5-flash",
    )
    c = build_cascade(cfg, env={})
    assert [t.name for t in c.rank_tiers] == ["gpt-5-mini|gemini-2.5-flash", "vllm-qwen2.5-vl"]
    assert [t.name for t in c.confirm_tiers] == ["gpt-5-mini|gemini-2.5-flash"]
    assert c.onboard.name == "onboard"


def test_unknown_reasoner_names_the_choices() -> None:
    with pytest.raises(
        ConfigError, match=r"reasoner.name: unknown reasoner 'gpt-7'; available: .*gpt-5-mini"
    ):
        build_cascade(ReasonerConfig(name="gpt-7"), env={})
    with pytest.raises(ConfigError, match=r"reasoner.rank_fallbacks: unknown reasoner 'edge'"):
        build_cascade(ReasonerConfig(name="gpt-5", rank_fallbacks=("edge",)), env={})


# ------------------------------------------------------------------------------------------ companion-eval
def _write(tmp_path: Path, name: str, rgb: np.ndarray) -> Path:
    path = tmp_path / name
    assert cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return path


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict[str, Any]]:
    status = eval_main(list(argv))
    out = capsys.readouterr().out
    return status, json.loads(out)


def test_eval_rank_and_confirm_onboard_on_image_files(
    tmp_path: Path, roofs: dict[str, np.ndarray], capsys: pytest.CaptureFixture[str]
) -> None:
    a = _write(tmp_path, "cluttered.png", roofs["cluttered"])
    b = _write(tmp_path, "clear.jpg", roofs["clear"])
    status, out = _run(capsys, "rank", "--reasoner", "onboard", str(a), str(b))
    assert status == 0
    assert out["ranking"] == [1, 0]
    assert out["tier"] == "onboard"
    assert out["rationale"]
    assert math.isfinite(out["latency_s"])
    status, out = _run(capsys, "confirm", str(b))
    assert (status, out["confirm"], out["tier"]) == (0, True, "onboard")
    status, out = _run(capsys, "confirm", str(a))
    assert (status, out["confirm"]) == (0, False)


def test_eval_rank_with_a_remote_tier_and_its_fallback(
    tmp_path: Path, server: ScriptedServer, roofs: dict[str, np.ndarray], capsys: pytest.CaptureFixture[str]
) -> None:
    server.script("edge-model", Reply(body=completion("The second looks best.")))
    config = tmp_path / "companion.toml"
    config.write_text(
        f'[reasoner]\nrank_deadline_s = 3.0\n[reasoner.profiles.edge]\nbase_url = "{server.base_url}"\n'
        'model = "edge-model"\nmax_attempts = 1\n'
    )
    a = _write(tmp_path, "cluttered.png", roofs["cluttered"])
    b = _write(tmp_path, "clear.png", roofs["clear"])
    status, out = _run(capsys, "rank", "--config", str(config), "--reasoner", "edge", str(a), str(b))
    assert status == 0
    assert out["tier"] == "onboard"
    assert out["ranking"] == [1, 0]
    assert out["errors"] == [{"tier": "edge", "kind": "malformed", "message": out["errors"][0]["message"]}]
    status, out = _run(
        capsys, "rank", "--config", str(config), "--reasoner", "edge", "--no-fallback", str(a), str(b)
    )
    assert status == 3
    assert out["error"]["kind"] == "malformed"
    assert out["tier"] == "edge"


def test_eval_bad_input_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "not-an-image.png"
    bad.write_text("hello")
    assert eval_main(["rank", str(bad)]) == 2
    assert "not a readable image" in capsys.readouterr().err
    assert eval_main(["confirm", "--reasoner", "gpt-7", str(bad)]) == 2
    img = _write(tmp_path, "x.png", np.zeros((20, 20, 3), np.uint8))
    assert eval_main(["confirm", "--reasoner", "gpt-7", str(img)]) == 2
    assert "unknown reasoner 'gpt-7'" in capsys.readouterr().err
