"""companion-bench images: a labelled folder of synthetic photographs end to end through the CLI (the
onboard tier), the case counting with a scripted stand-in reasoner, every kind of bad input, and the
real-photograph set when it is present (../shared/realimages; structure and counts only)."""

from __future__ import annotations

import html
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from companion.reasoning.base import ConfirmRequest, RankRequest
from landfall_eval import images as bench_images
from landfall_eval.cli import IMAGE_CONTEXTS
from landfall_eval.cli import main as bench_main
from landfall_eval.images import (
    CONTEXTS,
    SCHEMA,
    LabelsError,
    evaluate,
    load_folder,
    rank_pairs,
    side_by_side,
    write_images_report,
)

REAL = Path(__file__).resolve().parents[2] / "shared" / "realimages"
SUMMARY_KEYS = {
    "confirm_accuracy", "rank_accuracy", "confirm_cases", "rank_cases", "confirm_correct", "rank_correct",
    "false_accepts", "unsafe_cases", "false_accept_rate", "false_refusals", "safe_cases", "false_refuse_rate",
    "tiers",
}  # fmt: skip
IMAGE_KEYS = {
    "file", "label", "land", "what", "confirm", "correct", "rationale", "tier", "latency_s", "rank_cases",
    "rank_correct", "source",
}  # fmt: skip


# ------------------------------------------------------------------------------------------ synthetic folder
def _gravel(rng: np.random.Generator, base: float = 150.0, size: int = 200) -> np.ndarray:
    """A uniform grey gravel-like square (RGB): a clear roof."""
    grey = rng.normal(base, 12.0, (size, size, 1)).clip(0, 255)
    img = np.repeat(grey, 3, axis=2) + np.array([4.0, 2.0, -3.0])
    return cv2.GaussianBlur(img.astype(np.float32), (3, 3), 0).clip(0, 255).astype(np.uint8)


def _cluttered(rng: np.random.Generator) -> np.ndarray:
    """The gravel with dark boxes and the shadows they cast: a cluttered roof."""
    img = _gravel(rng).astype(np.int16)
    for _ in range(5):
        x, y = rng.integers(10, 150, 2)
        s = int(rng.integers(20, 40))
        img[y + 6 : y + s + 10, x + 6 : x + s + 10] -= 60
        img[y : y + s, x : x + s] = rng.integers(30, 70)
    return img.clip(0, 255).astype(np.uint8)


def _water(rng: np.random.Generator) -> np.ndarray:
    """A blue rippled square: water."""
    img = np.zeros((200, 200, 3), np.float32) + np.array([40.0, 90.0, 150.0], np.float32)
    img += rng.normal(0.0, 8.0, (200, 200, 1)).astype(np.float32)
    img[:, :, 2] += 10.0 * np.sin(np.arange(200) / 6.0)[None, :]
    return img.clip(0, 255).astype(np.uint8)


def _make_folder(root: Path) -> list[dict[str, Any]]:
    """2 clear roofs, 3 cluttered ones, one cluttered picture labelled a clear roof (a sure miss), water
    and an empty field (land null); PNG and JPEG. Returns the labels written."""
    rng = np.random.default_rng(3)
    (root / "images").mkdir(parents=True)
    pictures: list[tuple[str, str, bool | None, np.ndarray]] = [
        ("images/clear0.png", "clear_roof", True, _gravel(rng)),
        ("images/clear1.jpg", "clear_roof", True, _gravel(rng)),
        ("images/clutter0.jpg", "cluttered_roof", False, _cluttered(rng)),
        ("images/clutter1.png", "cluttered_roof", False, _cluttered(rng)),
        ("images/clutter2.jpg", "cluttered_roof", False, _cluttered(rng)),
        ("images/mislabelled.png", "clear_roof", True, _cluttered(rng)),
        ("images/water.png", "not_roof", False, _water(rng)),
        ("images/field.png", "not_roof", None, _gravel(rng, base=110.0)),
    ]
    labels = []
    for file, label, land, rgb in pictures:
        assert cv2.imwrite(str(root / file), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        source = "water/repo" if label == "not_roof" else "roofs/repo"
        labels.append(
            {"file": file, "label": label, "land": land, "what": f"synthetic {label}", "source_repo": source}
        )
    (root / "labels.json").write_text(json.dumps(labels, indent=1))
    return labels


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    _make_folder(tmp_path / "photos")
    return tmp_path / "photos"


def _labels(folder: Path) -> list[dict[str, Any]]:
    data: list[dict[str, Any]] = json.loads((folder / "labels.json").read_text())
    return data


def test_bench_images_synthetic_folder_end_to_end(folder: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    labels = _labels(folder)
    assert bench_main(["images", str(folder), "--reasoner", "onboard", "--out", str(out), "--quiet"]) == 0
    r = json.loads((out / "results.json").read_text())
    assert r["schema"] == SCHEMA == "landfall-bench-images/1"
    assert r["command"] == "images"
    assert r["config"] == {"dir": str(folder), "reasoner": "onboard", "context": "crop", "config": None}
    s = r["summary"]
    assert set(s) == SUMMARY_KEYS
    n_clear = sum(e["label"] == "clear_roof" for e in labels)
    n_cluttered = sum(e["label"] == "cluttered_roof" for e in labels)
    assert (n_clear, n_cluttered) == (3, 3)
    assert s["confirm_cases"] == sum(e["land"] is not None for e in labels) == 7
    assert s["rank_cases"] == 2 * n_clear * n_cluttered == 18
    assert s["confirm_accuracy"] == s["confirm_correct"] / s["confirm_cases"]
    assert s["rank_accuracy"] == s["rank_correct"] / s["rank_cases"]
    assert s["tiers"] == {"confirm": {"onboard": len(labels)}, "rank": {"onboard": 18}}
    assert set(r["by_label"]) == {"clear_roof", "cluttered_roof", "not_roof"}
    assert sum(v["cases"] for v in r["by_label"].values()) == s["confirm_cases"]
    assert sum(v["correct"] for v in r["by_label"].values()) == s["confirm_correct"]
    assert r["by_label"]["not_roof"]["cases"] == 1  # the field (land null) is no case
    for stage in ("confirm", "rank"):
        lat = r["latency_s"][stage]
        assert 0 <= lat["median"] <= lat["p90"] <= lat["max"]
    assert [i["file"] for i in r["images"]] == [e["file"] for e in labels]
    rank_cases_of = {"clear_roof": 2 * n_cluttered, "cluttered_roof": 2 * n_clear, "not_roof": 0}
    for img, entry in zip(r["images"], labels, strict=True):
        assert set(img) == IMAGE_KEYS
        assert (img["label"], img["land"], img["tier"]) == (entry["label"], entry["land"], "onboard")
        assert isinstance(img["confirm"], bool)
        assert img["correct"] == (None if entry["land"] is None else img["confirm"] == entry["land"])
        assert img["rationale"]
        assert img["rank_cases"] == rank_cases_of[img["label"]]
    # every rank case counts once for its clear roof: the clear roofs' tallies add up to the summary
    clear_rows = [i for i in r["images"] if i["label"] == "clear_roof"]
    assert sum(i["rank_correct"] for i in clear_rows) == s["rank_correct"]
    assert len(r["rank_misses"]) == s["rank_cases"] - s["rank_correct"]
    for m in r["rank_misses"]:
        assert m["clear"] in m["files"]
        assert m["ranking"][:1] != [m["files"].index(m["clear"])]
    # the cluttered picture labelled a clear roof is refused: a confirm miss, shown with its rationale
    confirm_misses = [i for i in r["images"] if i["correct"] is False]
    assert "images/mislabelled.png" in {i["file"] for i in confirm_misses}
    page = (out / "report.html").read_text()
    assert "<h2>Summary</h2>" in page
    assert "data:image/jpeg;base64," in page
    for miss in confirm_misses + r["rank_misses"]:
        assert html.escape(miss["rationale"]) in page
    assert not any(out.glob(".*.tmp"))


def test_bench_images_full_context_sends_the_pair_side_by_side(folder: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    argv = ["images", str(folder), "--context", "full", "--out", str(out), "--quiet"]
    assert bench_main(argv) == 0
    r = json.loads((out / "results.json").read_text())
    assert r["config"]["context"] == "full"
    assert r["summary"]["rank_cases"] == 18
    a, b = np.zeros((40, 60, 3), np.uint8), np.full((80, 40, 3), 9, np.uint8)
    joined = side_by_side(a, b)
    assert joined.shape == (40, 60 + 8 + 20, 3)  # b scaled to 40 rows keeps its aspect (20 columns)
    assert (joined[:, 60:68] == 255).all()
    assert (joined[:, 68:] == 9).all()
    assert IMAGE_CONTEXTS == CONTEXTS


# ------------------------------------------------------------------------------------------ counting
class ScriptedAsker:
    """Says yes to every confirm and ranks the first crop first, and records what it was asked."""

    def __init__(self) -> None:
        self.requests: list[RankRequest | ConfirmRequest] = []

    async def ask(self, request: RankRequest | ConfirmRequest) -> tuple[dict[str, Any], int]:
        self.requests.append(request)
        if isinstance(request, RankRequest):
            return {"ranking": [0, 1], "rationale": f"first of {len(self.requests)}", "tier": "scripted",
                    "latency_s": 0.25, "errors": []}, 0  # fmt: skip
        return {"confirm": True, "rationale": f"yes {len(self.requests)}", "tier": "scripted",
                "latency_s": 0.5, "errors": []}, 0  # fmt: skip


async def test_evaluate_counts_cases_from_the_labels(folder: Path, tmp_path: Path) -> None:
    images = load_folder(folder)
    asker = ScriptedAsker()
    seen: list[tuple[int, int, int, int]] = []
    figures = await evaluate(images, asker, context="full", progress=lambda *t: seen.append(t))
    # every image is asked to confirm, then every (clear, cluttered) pair in both orders
    assert len(asker.requests) == 8 + 18 == len(seen)
    assert all(isinstance(q, ConfirmRequest) and q.check is None for q in asker.requests[:8])
    ranks = [q for q in asker.requests[8:] if isinstance(q, RankRequest)]
    assert len(ranks) == 18
    assert all(len(q.crops) == 2 and q.candidates is None and q.context is not None for q in ranks)
    s = figures["summary"]
    # "yes" is right for the 3 clear roofs (land true) and wrong for the 4 with land false
    assert (s["confirm_cases"], s["confirm_correct"], s["confirm_accuracy"]) == (7, 3, 3 / 7)
    # every "yes" on a site labelled unsafe is a false accept; no safe site was refused
    assert (s["false_accepts"], s["unsafe_cases"], s["false_accept_rate"]) == (4, 4, 1.0)
    assert (s["false_refusals"], s["safe_cases"], s["false_refuse_rate"]) == (0, 3, 0.0)
    # per source (labels.json's source_repo): the water and the field, then the six roofs
    by = figures["by_source"]
    assert set(by) == {"roofs/repo", "water/repo"}
    assert (by["water/repo"]["confirm_cases"], by["water/repo"]["false_accepts"]) == (1, 1)
    assert by["water/repo"]["rank_cases"] == 0
    assert (by["roofs/repo"]["confirm_cases"], by["roofs/repo"]["confirm_correct"]) == (6, 3)
    assert (by["roofs/repo"]["false_accepts"], by["roofs/repo"]["unsafe_cases"]) == (3, 3)
    assert by["roofs/repo"]["rank_cases"] == 2 * 18  # every pair counts for both of its images
    # "first crop first" is right exactly when the clear roof was sent first: half the cases
    assert (s["rank_cases"], s["rank_correct"], s["rank_accuracy"]) == (18, 9, 0.5)
    assert figures["by_label"]["clear_roof"] == {"cases": 3, "correct": 3, "accuracy": 1.0}
    assert figures["by_label"]["not_roof"] == {"cases": 1, "correct": 0, "accuracy": 0.0}
    assert figures["latency_s"] == {
        "confirm": {"median": 0.5, "p90": 0.5, "max": 0.5},
        "rank": {"median": 0.25, "p90": 0.25, "max": 0.25},
    }
    assert seen[-1] == (3, 7, 9, 18)
    misses = figures["rank_misses"]
    assert len(misses) == 9
    assert all(m["files"][1] == m["clear"] and m["ranking"] == [0, 1] for m in misses)
    per_image = {i["file"]: (i["rank_cases"], i["rank_correct"]) for i in figures["images"]}
    assert per_image["images/clear0.png"] == (6, 3)
    assert per_image["images/water.png"] == (0, 0)
    # the report shows each confirm miss and each rank-miss pair once, both orders under one pair
    out = tmp_path / "report"
    out.mkdir()
    page = write_images_report({"config": {}, **figures}, out, folder).read_text()
    assert "Confirm misses (4)" in page
    assert "Rank misses (9 cases, 9 pairs)" in page
    for m in misses:
        assert html.escape(m["rationale"]) in page
    assert page.count("<img ") == 4 + 2 * 9


async def test_evaluate_without_cluttered_roofs_has_no_rank_accuracy(tmp_path: Path) -> None:
    root = tmp_path / "photos"
    _make_folder(root)
    (root / "labels.json").write_text(
        json.dumps([e for e in _labels(root) if e["label"] != "cluttered_roof"])
    )
    figures = await evaluate(load_folder(root), ScriptedAsker())
    assert figures["summary"]["rank_cases"] == 0
    assert figures["summary"]["rank_accuracy"] is None
    assert figures["latency_s"]["rank"] == {"median": None, "p90": None, "max": None}
    assert figures["by_label"]["cluttered_roof"] == {"cases": 0, "correct": 0, "accuracy": None}


def test_rank_pairs_puts_each_pair_in_both_orders(folder: Path) -> None:
    pairs = [(a.file, b.file) for a, b in rank_pairs(load_folder(folder))]
    assert len(pairs) == len(set(pairs)) == 18
    assert ("images/clear0.png", "images/clutter0.jpg") in pairs
    assert ("images/clutter0.jpg", "images/clear0.png") in pairs


# ------------------------------------------------------------------------------------------ bad input
Edit = Callable[[Path, list[dict[str, Any]]], object]


def _relabel(**fields: Any) -> Edit:
    def edit(root: Path, labels: list[dict[str, Any]]) -> None:
        labels[1].update(fields)
        (root / "labels.json").write_text(json.dumps(labels))

    return edit


def _drop(key: str) -> Edit:
    def edit(root: Path, labels: list[dict[str, Any]]) -> None:
        del labels[1][key]
        (root / "labels.json").write_text(json.dumps(labels))

    return edit


def _write_labels(text: str) -> Edit:
    return lambda root, labels: (root / "labels.json").write_text(text)


def _not_an_image(root: Path, labels: list[dict[str, Any]]) -> None:
    (root / labels[1]["file"]).write_text("not a picture")


BAD_INPUT: dict[str, tuple[Edit, str]] = {
    "no labels.json": (lambda root, labels: (root / "labels.json").unlink(), "no labels.json in it"),
    "invalid JSON": (_write_labels("[{"), "labels.json: not valid JSON"),
    "not a list": (
        _write_labels('{"file": "images/clear0.png"}'),
        "expected a list of entries, got a JSON object",
    ),
    "entry not an object": (
        _write_labels('[["images/clear0.png"]]'),
        "labels.json entry 1: expected an object",
    ),
    "no file": (_drop("file"), "labels.json entry 2: no 'file'"),
    "file not a path": (
        _relabel(file=7),
        "labels.json entry 2: 'file' must be a path relative to the folder",
    ),
    "no label": (_drop("label"), "labels.json entry 2 (images/clear1.jpg): no 'label'"),
    "unknown label": (
        _relabel(label="roof"),
        "labels.json entry 2 (images/clear1.jpg): label 'roof' is not one of "
        "clear_roof, cluttered_roof, not_roof",
    ),
    "no land": (_drop("land"), "labels.json entry 2 (images/clear1.jpg): no 'land'"),
    "land a string": (
        _relabel(land="yes"),
        'entry 2 (images/clear1.jpg): land "yes" is not true, false or null',
    ),
    "land a number": (_relabel(land=1), "entry 2 (images/clear1.jpg): land 1 is not true, false or null"),
    "missing file": (_relabel(file="images/gone.jpg"), "labels.json entry 2 (images/gone.jpg): no such file"),
    "not an image": (_not_an_image, "labels.json entry 2 (images/clear1.jpg): "),
    "the same file twice": (
        _relabel(file="images/clear0.png"),
        "labels.json entry 2 (images/clear0.png): the same file as entry 1",
    ),
}


@pytest.mark.parametrize("case", list(BAD_INPUT))
def test_bench_images_bad_input_names_the_entry_and_writes_nothing(
    case: str, folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    edit, message = BAD_INPUT[case]
    edit(folder, _labels(folder))
    out = tmp_path / "out"
    assert bench_main(["images", str(folder), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.startswith("companion-bench images: ")
    if case == "not an image":
        assert "not a readable image" in err
    assert not out.exists()


def test_bench_images_missing_folder_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert bench_main(["images", str(tmp_path / "nowhere"), "--out", str(out)]) == 2
    assert f"{tmp_path / 'nowhere'}: no such folder" in capsys.readouterr().err
    assert not out.exists()


def test_bench_images_two_channel_image_is_refused(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # cv2.imread with IMREAD_COLOR gives 3 channels for any file it reads; a decoder that does not is
    # simulated here, for the one entry
    real_imread = cv2.imread

    def imread(path: str, flags: int = cv2.IMREAD_COLOR) -> np.ndarray | None:
        img = real_imread(path, flags)
        return img[:, :, :2].copy() if img is not None and path.endswith("clutter1.png") else img

    monkeypatch.setattr(bench_images.cv2, "imread", imread)
    out = tmp_path / "out"
    assert bench_main(["images", str(folder), "--out", str(out), "--quiet"]) == 2
    assert "labels.json entry 4 (images/clutter1.png): " in (err := capsys.readouterr().err)
    assert "not a 3-channel 8-bit image" in err
    assert not out.exists()


def test_load_folder_error_carries_the_entry(folder: Path) -> None:
    _relabel(label="roof")(folder, _labels(folder))
    with pytest.raises(LabelsError, match=r"label 'roof'") as info:
        load_folder(folder)
    assert (info.value.entry, info.value.file) == (2, "images/clear1.jpg")


def test_bench_images_unknown_reasoner_exits_2(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert bench_main(["images", str(folder), "--reasoner", "gpt-7", "--out", str(out), "--quiet"]) == 2
    assert "unknown reasoner 'gpt-7'" in capsys.readouterr().err
    assert not out.exists()


def test_bench_images_keeps_another_commands_results(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    city = '{"schema": "landfall-bench/1", "episodes": []}\n'
    (out / "results.json").write_text(city)
    assert bench_main(["images", str(folder), "--out", str(out), "--quiet"]) == 2
    assert "not a companion-bench images results file" in capsys.readouterr().err
    assert (out / "results.json").read_text() == city
    assert not (out / "report.html").exists()


# ------------------------------------------------------------------------------------------ real photographs
@pytest.mark.slow
def test_bench_images_real_photographs(tmp_path: Path) -> None:
    if not (REAL / "labels.json").is_file():
        pytest.skip(
            "../shared/realimages is not here: it is the project's shared real-photograph set; CI has it"
        )
    labels = json.loads((REAL / "labels.json").read_text())
    out = tmp_path / "out"
    assert bench_main(["images", str(REAL), "--reasoner", "onboard", "--out", str(out), "--quiet"]) == 0
    r = json.loads((out / "results.json").read_text())
    s = r["summary"]
    assert len(r["images"]) == len(labels) == 62
    assert s["confirm_cases"] == sum(e["land"] is not None for e in labels)
    assert s["rank_cases"] == 2 * 18 * 22 == 792
    assert sum(v["cases"] for v in r["by_label"].values()) == s["confirm_cases"]
    assert len(r["rank_misses"]) == s["rank_cases"] - s["rank_correct"]
    assert (out / "report.html").stat().st_size > 0
