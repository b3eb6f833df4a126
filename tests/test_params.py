"""The companion's settings as MAVLink parameters (companion/params.py), at its link: the list, a read
by name or index, a set applied at once and kept across a restart, and refusals (a value out of range
or that would make the inhibit band upside down, a sender that may not command, an unknown name) with
the value in force sent back and a STATUSTEXT saying why; a file that cannot be used loses nothing."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.daemon import Companion
from companion.flavour import Mode
from companion.operator import InhibitSwitch
from companion.params import MAV_PARAM_TYPE_REAL32, PARAMS
from tests.fake_link import FakeLink

GCS = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
OTHER = mavlink2.MAVLink(None, srcSystem=42, srcComponent=190)


def _name(msg: Any) -> str:
    raw = msg.param_id
    return (raw if isinstance(raw, str) else bytes(raw).decode()).rstrip("\0")


def _values(link: FakeLink) -> dict[str, float]:
    return {_name(m): float(m.param_value) for m in link.sent_of("PARAM_VALUE")}


def _texts(link: FakeLink) -> list[str]:
    out = []
    for m in link.sent_of("STATUSTEXT"):
        text = m.text if isinstance(m.text, str) else bytes(m.text).decode()
        out.append(text.rstrip("\0"))
    return out


def _set(link: FakeLink, name: str, value: float, sender: Any = GCS, component: int = 191) -> None:
    link.receive(
        sender.param_set_encode(1, component, name.encode(), value, MAV_PARAM_TYPE_REAL32).pack(sender)
    )


def _companion(tmp_path: Path | None = None, **kwargs: Any) -> tuple[Companion, FakeLink]:
    link = FakeLink()
    params_file = tmp_path / "params.json" if tmp_path is not None else None
    return Companion(link=link, params_file=params_file, **kwargs), link


def test_the_list_and_reads_by_name_and_index_answer_the_asker() -> None:
    c, link = _companion(inhibit=InhibitSwitch(7, (1700, 2100)), cancel_to="rtl", watch_battery_pct=20.0)
    link.receive(GCS.param_request_list_encode(1, 0).pack(GCS))  # component 0: every component
    values = link.sent_of("PARAM_VALUE")
    assert [_name(m) for m in values] == [p.name for p in PARAMS]
    assert [m.param_index for m in values] == list(range(len(PARAMS)))
    assert {m.param_count for m in values} == {len(PARAMS)}
    assert {m.param_type for m in values} == {MAV_PARAM_TYPE_REAL32}
    assert set(link.sent_to) == {(255, 190)}
    assert _values(link) == {
        "LF_CANCEL_MODE": 2.0, "LF_INH_RC_CH": 7.0, "LF_INH_PWM_LO": 1700.0, "LF_INH_PWM_HI": 2100.0,
        "LF_BATT_CRIT": 20.0, "LF_WATCH_FS": 1.0, "LF_WATCH_GPS": 1.0,
    }  # fmt: skip
    link.sent.clear()
    link.receive(GCS.param_request_read_encode(1, 191, b"LF_INH_RC_CH", -1).pack(GCS))
    link.receive(GCS.param_request_read_encode(1, 191, b"", 0).pack(GCS))
    link.receive(GCS.param_request_read_encode(1, 191, b"NO_SUCH", -1).pack(GCS))  # no answer
    link.receive(GCS.param_request_list_encode(1, 1).pack(GCS))  # the autopilot's, not ours
    assert [_name(m) for m in link.sent_of("PARAM_VALUE")] == ["LF_INH_RC_CH", "LF_CANCEL_MODE"]
    assert c.param_server.refused == 0


def test_a_set_applies_at_once_answers_with_the_value_and_is_kept_for_the_next_start(tmp_path: Path) -> None:
    async def scenario() -> None:
        c, link = _companion(tmp_path)
        _set(link, "LF_INH_RC_CH", 8)
        _set(link, "LF_CANCEL_MODE", 1)
        _set(link, "LF_BATT_CRIT", 0)  # the battery watcher off
        assert c.operator.inhibit == InhibitSwitch(8, (1800, 2200))
        assert c.operator.cancel_mode is Mode.LAND
        assert _values(link)["LF_INH_RC_CH"] == 8.0
        assert link.sent_to[-1] is None  # the value in force goes to every peer
        kept = json.loads((tmp_path / "params.json").read_text())
        assert kept["LF_INH_RC_CH"] == 8
        assert kept["LF_BATT_CRIT"] == 0
        again, _ = _companion(tmp_path, cancel_to="hold")  # a restart: the kept values win
        assert again.operator.cancel_mode is Mode.LAND
        assert again.operator.inhibit == InhibitSwitch(8, (1800, 2200))

    asyncio.run(scenario())


def test_refused_sets_keep_the_value_say_why_and_are_counted(tmp_path: Path) -> None:
    c, link = _companion(tmp_path, accept_from=(255,), inhibit=InhibitSwitch(7))
    _set(link, "LF_INH_RC_CH", 19)  # out of range
    _set(link, "LF_INH_RC_CH", 7.5)  # not whole
    _set(link, "LF_INH_PWM_HI", 1700)  # under the band's low end, 1800: upside down
    _set(link, "LF_INH_RC_CH", 5, sender=OTHER)  # a system that may not command
    _set(link, "LF_NOPE", 1)
    _set(link, "LF_INH_RC_CH", 3, component=1)  # the autopilot's parameter: not ours, not answered
    assert c.operator.inhibit == InhibitSwitch(7)
    assert c.param_server.refused == 5
    assert _texts(link) == [
        "LF_INH_RC_CH: 19 outside 0..18",
        "LF_INH_RC_CH: 7.5 is not a whole number",
        "LF_INH_PWM: band 1800..1700, low above high",
        "LF_INH_RC_CH: system 42 may not change settings",
        "LF_NOPE: no such parameter",
    ]
    sent = [_name(m) for m in link.sent_of("PARAM_VALUE")]
    assert sent == ["LF_INH_RC_CH", "LF_INH_RC_CH", "LF_INH_PWM_HI", "LF_INH_RC_CH"]  # the values in force
    assert {float(m.param_value) for m in link.sent_of("PARAM_VALUE") if _name(m) == "LF_INH_RC_CH"} == {7.0}
    assert not (tmp_path / "params.json").exists()  # nothing changed, nothing written


def test_a_params_file_that_cannot_be_used_loses_nothing(tmp_path: Path) -> None:
    (tmp_path / "params.json").write_text("{not json")
    c, _ = _companion(tmp_path, cancel_to="rtl")
    assert c.operator.cancel_mode is Mode.RTL  # the configuration's value stands
    (tmp_path / "params.json").write_text(json.dumps({"LF_CANCEL_MODE": 7, "LF_WATCH_GPS": 0, "X": 1}))
    c, _ = _companion(tmp_path, cancel_to="rtl")
    assert c.operator.cancel_mode is Mode.RTL  # 7 is out of range: left out
    assert c._watch_gps is False  # the good entry applies
