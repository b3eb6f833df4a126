"""companion.record: JSON-lines events, images and arrays written atomically, size bound, secrets masked."""

from __future__ import annotations

import errno
import json
import logging
import os
import threading
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from pydantic import SecretStr

from companion.record import EVENTS_FILE, REDACTED, FlightRecord, NullRecord, open_record

MIB = 1024 * 1024


def read_events(path: Path) -> list[dict[str, Any]]:
    text = path.read_text()
    assert text == "" or text.endswith("\n"), "last line is torn"
    return [json.loads(line) for line in text.splitlines()]


def leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.endswith(".tmp"))


class Colour(Enum):
    RED = "red"


@dataclass(frozen=True)
class Pose:
    pos_ned_m: tuple[float, float, float]
    yaw_rad: float


# --- events ------------------------------------------------------------------------------------------


def test_record_event_writes_valid_json_lines(tmp_path: Path) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    rec.record_event("state", {"state": "acquire", "round": 1})
    rec.record_event(
        "rank",
        {
            "order": np.array([2, 0, 1]),
            "score": np.float32(0.5),
            "bad": float("nan"),
            "pose": Pose((1.0, 2.0, -30.0), 0.25),
            "colour": Colour.RED,
            "image": tmp_path / "a.jpg",
            "rationale": 'flat "roof"\nno clutter',
        },
    )
    rec.close()
    rows = read_events(tmp_path / "s1" / EVENTS_FILE)
    assert [r["seq"] for r in rows] == [0, 1]
    assert [r["kind"] for r in rows] == ["state", "rank"]
    assert rows[0]["round"] == 1
    assert rows[0]["time_mono_s"] <= rows[1]["time_mono_s"]
    assert rows[1]["order"] == [2, 0, 1]
    assert rows[1]["score"] == 0.5
    assert rows[1]["bad"] is None
    assert rows[1]["pose"] == {"pos_ned_m": [1.0, 2.0, -30.0], "yaw_rad": 0.25}
    assert rows[1]["colour"] == "red"
    assert rows[1]["image"] == str(tmp_path / "a.jpg")
    assert rows[1]["rationale"] == 'flat "roof"\nno clutter'


def test_record_event_masks_secrets_recursively(tmp_path: Path) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    rec.record_event(
        "link",
        {
            "api_key": "sk-live-123",
            "Signing_Key": "00ff00ff",
            "nested": {"Authorization": "Bearer abc.def", "items": [{"refresh_TOKEN": "tok-9"}], "ok": 3},
            "client_secret": {"inner": "s3cr3t"},
            "raw": b"\x01\x02hidden-bytes",
            "wrapped": SecretStr("pydantic-secret"),
            "note": "fine",
        },
    )
    text = (tmp_path / "s1" / EVENTS_FILE).read_text()
    for secret in (
        "sk-live-123",
        "00ff00ff",
        "abc.def",
        "tok-9",
        "s3cr3t",
        "hidden-bytes",
        "pydantic-secret",
    ):
        assert secret not in text
    (row,) = read_events(tmp_path / "s1" / EVENTS_FILE)
    assert row["api_key"] == REDACTED
    assert row["Signing_Key"] == REDACTED
    assert row["nested"] == {"Authorization": REDACTED, "items": [{"refresh_TOKEN": REDACTED}], "ok": 3}
    assert row["client_secret"] == REDACTED
    assert row["raw"] == "<14 bytes>"
    assert row["wrapped"] == REDACTED
    assert row["note"] == "fine"


def test_record_event_rejects_reserved_field_names(tmp_path: Path) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    with pytest.raises(ValueError, match=r"reserved field names \['kind', 'seq'\]"):
        rec.record_event("x", {"kind": 1, "seq": 2})
    assert not (tmp_path / "s1" / EVENTS_FILE).exists()


def test_record_event_continues_an_existing_session(tmp_path: Path) -> None:
    with FlightRecord(tmp_path, max_mb=10, session="s1") as rec:
        rec.record_event("a", {})
        rec.record_event("b", {})
    with FlightRecord(tmp_path, max_mb=10, session="s1") as rec:
        rec.record_event("c", {})
    rows = read_events(tmp_path / "s1" / EVENTS_FILE)
    assert [(r["seq"], r["kind"]) for r in rows] == [(0, "a"), (1, "b"), (2, "c")]


def test_record_event_from_many_threads_keeps_every_line(tmp_path: Path) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    start = threading.Barrier(8)

    def worker(n: int) -> None:
        start.wait()
        for i in range(20):
            rec.record_event("tick", {"thread": n, "i": i})

    threads = [threading.Thread(target=worker, args=(n,)) for n in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    rows = read_events(tmp_path / "s1" / EVENTS_FILE)
    assert len(rows) == 160
    assert sorted(r["seq"] for r in rows) == list(range(160))
    assert {(r["thread"], r["i"]) for r in rows} == {(n, i) for n in range(8) for i in range(20)}


def test_flight_record_default_session_is_fresh_directory(tmp_path: Path) -> None:
    a = FlightRecord(tmp_path, max_mb=10)
    b = FlightRecord(tmp_path, max_mb=10)
    assert a.session != b.session
    assert a.session_dir.is_dir()
    assert b.session_dir.is_dir()
    assert a.session_dir.parent == tmp_path


def test_flight_record_closed_refuses_writes(tmp_path: Path) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    rec.close()
    rec.close()
    with pytest.raises(ValueError, match="closed"):
        rec.record_event("late", {})


@pytest.mark.parametrize("session", ["", "..", "a/b", "../up", ".hidden"])
def test_flight_record_rejects_unsafe_session_names(tmp_path: Path, session: str) -> None:
    with pytest.raises(ValueError, match="session must be a plain name"):
        FlightRecord(tmp_path, max_mb=10, session=session)


def test_flight_record_rejects_bad_max_mb(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="max_mb must be >= 1, got 0"):
        FlightRecord(tmp_path, max_mb=0)


# --- images and arrays -------------------------------------------------------------------------------


def test_save_image_writes_decodable_jpeg_in_rgb_order(tmp_path: Path) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    rgb = np.zeros((54, 96, 3), dtype=np.uint8)
    rgb[..., 0] = 220  # red
    path = rec.save_image("round01-frame", rgb)
    assert path == tmp_path / "s1" / "round01-frame.jpg"
    bgr = cv2.imread(str(path))
    assert bgr is not None
    assert bgr.shape == (54, 96, 3)
    b, g, r = (float(bgr[..., c].mean()) for c in range(3))
    assert r > 200
    assert b < 20
    assert g < 20
    assert rec.save_image("crop.jpg", rgb[:10, :10]) == tmp_path / "s1" / "crop.jpg"
    assert leftovers(tmp_path / "s1") == []


@pytest.mark.parametrize(
    "bad",
    [np.zeros((10, 10), np.uint8), np.zeros((10, 10, 4), np.uint8), np.zeros((10, 10, 3), np.float32), [[1]]],
)
def test_save_image_rejects_non_rgb_uint8(tmp_path: Path, bad: Any) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    with pytest.raises(ValueError, match=r"expected an \(H, W, 3\) uint8 RGB array"):
        rec.save_image("x", bad)


@pytest.mark.parametrize("name", ["", "../x", "a/b", ".hidden", "a b", "x" * 200])
def test_save_image_rejects_unsafe_names(tmp_path: Path, name: str) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    with pytest.raises(ValueError, match="record file name must match"):
        rec.save_image(name, np.zeros((4, 4, 3), np.uint8))


def test_save_array_round_trips_without_pickle(tmp_path: Path) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    depth = np.arange(12, dtype=np.float32).reshape(3, 4)
    path = rec.save_array("round01-depth", depth)
    assert path == tmp_path / "s1" / "round01-depth.npy"
    np.testing.assert_array_equal(np.load(path, allow_pickle=False), depth)
    with pytest.raises(ValueError, match="expected a numeric ndarray"):
        rec.save_array("objects", np.array([object()]))


# --- crashes mid-write -------------------------------------------------------------------------------


def test_record_event_crash_before_replace_keeps_previous_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    rec.record_event("a", {"n": 1})
    rec.record_event("b", {"n": 2, "text": "x" * 5000})
    events = tmp_path / "s1" / EVENTS_FILE
    before = events.read_bytes()
    calls: list[tuple[str, str]] = []

    def power_cut(src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> None:
        calls.append((str(src), str(dst)))
        assert Path(src).stat().st_size > len(before)  # the temporary file was fully written
        raise RuntimeError("power cut")

    with monkeypatch.context() as m:
        m.setattr(os, "replace", power_cut)
        with pytest.raises(RuntimeError, match="power cut"):
            rec.record_event("c", {"n": 3, "text": "y" * 5000})
    assert len(calls) == 1
    assert Path(calls[0][1]) == events
    assert Path(calls[0][0]).parent == events.parent  # same directory, so the rename is atomic
    assert events.read_bytes() == before
    assert [r["kind"] for r in read_events(events)] == ["a", "b"]
    assert leftovers(tmp_path / "s1") == []
    rec.record_event("d", {"n": 4})
    assert [(r["seq"], r["kind"]) for r in read_events(events)] == [(0, "a"), (1, "b"), (2, "d")]


def test_record_event_disk_error_is_logged_not_raised(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    rec.record_event("a", {})
    events = tmp_path / "s1" / EVENTS_FILE
    before = events.read_bytes()

    def disk_full(src: object, dst: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    with monkeypatch.context() as m, caplog.at_level(logging.WARNING, logger="companion.record"):
        m.setattr(os, "replace", disk_full)
        rec.record_event("b", {"api_key": "never-logged"})
        assert rec.save_image("frame", np.zeros((4, 4, 3), np.uint8)) is None
    assert rec.failures == 2
    assert "No space left on device" in caplog.text
    assert "never-logged" not in caplog.text
    assert events.read_bytes() == before
    assert leftovers(tmp_path / "s1") == []


def test_save_image_crash_keeps_previous_image(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rec = FlightRecord(tmp_path, max_mb=10, session="s1")
    path = rec.save_image("frame", np.full((8, 8, 3), 200, np.uint8))
    assert path is not None
    before = path.read_bytes()

    def power_cut(src: object, dst: object) -> None:
        raise RuntimeError("power cut")

    with monkeypatch.context() as m:
        m.setattr(os, "replace", power_cut)
        with pytest.raises(RuntimeError):
            rec.save_image("frame", np.zeros((8, 8, 3), np.uint8))
    assert path.read_bytes() == before
    assert leftovers(tmp_path / "s1") == []


# --- size bound --------------------------------------------------------------------------------------


def make_old_session(root: Path, name: str, size: int, mtime: float) -> Path:
    session = root / name
    session.mkdir()
    (session / EVENTS_FILE).write_text('{"kind":"old"}\n')
    (session / "frame.jpg").write_bytes(b"\0" * size)
    os.utime(session, (mtime, mtime))
    return session


def test_size_bound_deletes_oldest_sessions_first(tmp_path: Path) -> None:
    # Three old sessions of 0.9 MiB under a 2 MiB bound: only the oldest has to go.
    oldest = make_old_session(tmp_path, "zz-oldest", int(0.9 * MIB), 1_000_000)
    middle = make_old_session(tmp_path, "aa-middle", int(0.9 * MIB), 2_000_000)
    newest = make_old_session(tmp_path, "mm-newest", int(0.9 * MIB), 3_000_000)
    rec = FlightRecord(tmp_path, max_mb=2, session="current")
    rec.record_event("start", {})
    assert not oldest.exists()
    assert middle.exists()
    assert newest.exists()
    assert (tmp_path / "current" / EVENTS_FILE).exists()
    # Another 0.5 MiB in the current session pushes the next oldest out.
    rec.save_array("depth", np.zeros(int(0.5 * MIB), np.uint8))
    assert not middle.exists()
    assert newest.exists()
    assert (tmp_path / "current" / "depth.npy").exists()


def test_size_bound_prunes_own_files_but_never_events(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    rec = FlightRecord(tmp_path, max_mb=1, session="current")
    rec.record_event("start", {})
    with caplog.at_level(logging.INFO, logger="companion.record"):
        for i in range(4):
            rec.save_array(f"a{i}", np.zeros(int(0.4 * MIB), np.uint8))
            rec.record_event("saved", {"i": i})
    names = sorted(p.name for p in (tmp_path / "current").iterdir())
    assert names == ["a2.npy", "a3.npy", EVENTS_FILE]
    assert [r["kind"] for r in read_events(tmp_path / "current" / EVENTS_FILE)] == ["start"] + ["saved"] * 4
    assert "alone exceeds the bound" in caplog.text


def test_size_bound_counts_files_already_under_root(tmp_path: Path) -> None:
    (tmp_path / "stray.bin").write_bytes(b"\0" * (2 * MIB))
    os.utime(tmp_path / "stray.bin", (1_000_000, 1_000_000))
    rec = FlightRecord(tmp_path, max_mb=1, session="current")
    rec.record_event("start", {})
    assert not (tmp_path / "stray.bin").exists()
    assert (tmp_path / "current" / EVENTS_FILE).exists()


# --- the null record ---------------------------------------------------------------------------------


def test_open_record_without_dir_gives_null_record(tmp_path: Path) -> None:
    null = open_record(None, 500)
    assert isinstance(null, NullRecord)
    with null:
        null.record_event("x", {"api_key": "k"})
        assert null.save_image("x", np.zeros((2, 2, 3), np.uint8)) is None
        assert null.save_array("x", np.zeros(2)) is None
    assert null.failures == 0
    rec = open_record(tmp_path / "rec", 5, "s1")
    assert isinstance(rec, FlightRecord)
    assert rec.session_dir == tmp_path / "rec" / "s1"
    assert list((tmp_path / "rec" / "s1").iterdir()) == []


def test_interrupted_alarm_is_the_previous_sessions_alarm_without_an_outcome(tmp_path: Path) -> None:
    def session(name: str, lines: list[str]) -> None:
        (tmp_path / name).mkdir()
        (tmp_path / name / "events.jsonl").write_text("\n".join(lines) + "\n")

    alarm = json.dumps({"kind": "alarm", "reason": "GPS spoofing", "criticality": "high"})
    outcome = json.dumps({"kind": "outcome", "state": "landed"})
    assert FlightRecord(tmp_path / "empty", 10).interrupted_alarm() is None  # no earlier session
    session("20261123T100000Z-1", [alarm])  # older: not the previous one
    session("20261123T110000Z-2", [alarm, outcome])  # finished
    assert FlightRecord(tmp_path, 10).interrupted_alarm() is None
    session("20261123T120000Z-3", [outcome, alarm, '{"kind": "state", "sta'])  # killed mid-write
    found = FlightRecord(tmp_path, 10).interrupted_alarm()
    assert found is not None
    assert found["reason"] == "GPS spoofing"
