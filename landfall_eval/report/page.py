"""companion-bench's report: PNG figures and one HTML page from a results dict (``landfall-bench/1``).

:func:`write_report` writes ``out_dir/report.html`` and ``out_dir/figures/*.png``; the page links the
figures by relative path, so the folder can be moved or archived whole. Every section is optional: a
run with only the module checks, only episodes, or an empty episode list gives a page with what there
is. Every text taken from the results is HTML-escaped.

Figures: a bird's-eye map per scenario (the world's classes from simbridge's ground truth, each
episode's launch, track and touchdown, coloured by verdict), touchdown surfaces per (reasoner, context),
a histogram of reasoning rounds and the rationale clusters. Needs the ``bench`` extra (matplotlib; the
clusters also need the sentence-embedding model, and without it the page says so instead)."""

from __future__ import annotations

import importlib.util
from collections import Counter, defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from landfall_eval.basemap import BaseMap
from landfall_eval.rationales import MIN_TO_CLUSTER, EmbeddingsUnavailable, cluster_rationales
from landfall_eval.stats import safe_interval
from landfall_eval.study import (
    STUDY_JACCARD,
    STUDY_LANDING_DISTANCE_M,
    STUDY_PEAK_RSS_MB,
    STUDY_ROUNDS_PER_SAFE,
    STUDY_SAFE_RATE,
)

if TYPE_CHECKING:
    pass

from landfall_eval.report.episodes import (
    INSTALL_HINT,
    Episode,
    MatplotlibUnavailable,
    ReportError,
    as_list,
    as_mapping,
    as_number,
    read_episode,
)
from landfall_eval.report.figures import cluster_figure, map_figure, rounds_figure, surface_figure, thumbnail
from landfall_eval.report.markup import (
    NA,
    PAGE,
    escape,
    fmt,
    header,
    img_tag,
    mean_of,
    median_of,
    pct,
    short,
    slug,
    table,
    unique_name,
)

_MAX_FAILURES_SHOWN = 12  # per class; the episode table has them all


_STATS, _STATS2 = ("mean", "min", "max"), ("mean", "median", "max")  # Jaccard, landing distance columns


def write_report(
    results: Mapping[str, Any], out_dir: Path, *, basemaps: Mapping[str, BaseMap] | None = None
) -> Path:
    """Write ``out_dir/report.html`` and its figures under ``out_dir/figures``.

    Args:
        results: a ``landfall-bench/1`` results dict (see the harness's docs); any key may be missing.
        out_dir: created if needed; existing files of the same names are replaced.
        basemaps: map backgrounds by scenario name, to skip building them (a city takes seconds);
            scenarios not in it are drawn from simbridge's ground truth.

    Returns:
        The path of ``report.html``.

    Raises:
        MatplotlibUnavailable: matplotlib is not installed.
        ReportError: ``results`` is not a mapping, or its ``episodes`` is not a list.
    """
    if importlib.util.find_spec("matplotlib") is None:
        raise MatplotlibUnavailable(f"the companion-bench report needs matplotlib: {INSTALL_HINT}")
    if not isinstance(results, Mapping):
        raise ReportError(
            f"results must be a mapping (a landfall-bench/1 dict), got {type(results).__name__}"
        )
    raw_eps = results.get("episodes")
    if raw_eps is not None and not isinstance(raw_eps, list):
        raise ReportError(f"results['episodes'] must be a list, got {type(raw_eps).__name__}")
    config: Mapping[str, Any] = results.get("config") or {}
    if not isinstance(config, Mapping):
        raise ReportError(f"results['config'] must be a mapping, got {type(config).__name__}")
    episodes = [read_episode(i, e, config) for i, e in enumerate(raw_eps or [], 1) if isinstance(e, Mapping)]
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)

    parts = [header(results, config), _summary(results, episodes)]
    modules = results.get("modules")
    if isinstance(modules, Mapping) and modules:
        parts.append(_modules(modules))
    if raw_eps is not None:
        parts.append(_landings(episodes, config, fig_dir, basemaps or {}))
    if episodes:
        parts += [
            _latency(episodes),
            _weather(episodes),
            _failures(episodes, config, fig_dir),
            _clusters(episodes, fig_dir),
            _episode_table(episodes),
        ]
    page = PAGE.format(
        title=escape(f"companion-bench: {results.get('command', 'results')}"), body="\n".join(parts)
    )
    path = out_dir / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def write_episode_report(entry: Mapping[str, Any], out_dir: Path, record_dir: Path | None = None) -> Path:
    """One episode's page (what the demo writes): the verdict, the trajectory over the map and, from
    the flight record in ``record_dir``, the drone's-eye frame of each round with the candidates
    boxed, the chosen one in green and the reasoner's rationale beside it, then each confirmation's
    close-up with its verdict. Returns the path of ``out_dir/report.html``.

    Raises:
        MatplotlibUnavailable: matplotlib is not installed.
    """
    from landfall_eval.rounds import rounds_html

    if importlib.util.find_spec("matplotlib") is None:
        raise MatplotlibUnavailable(f"the episode report needs matplotlib: {INSTALL_HINT}")
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    ep = read_episode(1, entry, {})
    rows = [
        ("scenario", ep.scenario),
        ("surface at touchdown", entry.get("surface", NA)),
        ("safe", f"{entry.get('safe')} {'; '.join(as_list(entry.get('reasons')))}".strip()),
        ("rounds", entry.get("rounds", NA)),
        ("time from taking control to touchdown", fmt(as_number(entry.get("time_to_touchdown_s")), 1, " s")),
        ("over the kinematic lower bound", fmt(as_number(entry.get("kinematic_ratio")), 2, "x")),
    ]
    parts = [
        f"<h1>Landfall episode: {escape(entry.get('id', ep.scenario))}</h1>",
        table(("", ""), rows),
        "<h2>Trajectory</h2>",
    ]
    notes = map_figure(ep.scenario, [ep], {}, None, fig_dir / "map.png")
    parts.append(img_tag("map.png", f"bird's-eye map of {ep.scenario} with the trajectory"))
    parts += notes
    parts.append(rounds_html(record_dir, fig_dir) if record_dir is not None else "")
    page = PAGE.format(title=escape(f"Landfall episode {entry.get('id', '')}"), body="\n".join(parts))
    path = out_dir / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def _summary(results: Mapping[str, Any], eps: list[Episode]) -> str:
    given = as_mapping(results.get("summary"))
    interval: tuple[float, float] | None = None
    if eps:
        n = len(eps)
        safe = [e for e in eps if e.verdict == "safe"]
        safe_rate: float | None = len(safe) / n
        rounds_safe = mean_of(None if e.rounds is None else float(e.rounds) for e in safe)
        interval = safe_interval(len(safe), n)
    elif given:
        n = int(as_number(given.get("episodes")) or 0)  # 0 where the count is missing
        safe_rate, rounds_safe = as_number(given.get("safe_rate")), as_number(given.get("mean_rounds_safe"))
        got = given.get("safe_rate_interval_95")
        if isinstance(got, list) and len(got) == 2 and all(as_number(v) is not None for v in got):
            interval = (float(got[0]), float(got[1]))
    else:
        return ""
    safe_text = pct(safe_rate)
    if interval is not None:
        safe_text += f" (95 % interval {100 * interval[0]:.1f}-{100 * interval[1]:.1f} %)"
    rss = [e.peak_rss_mb for e in eps if e.peak_rss_mb is not None]
    outcomes = Counter(e.outcome for e in eps)
    rows = [
        ("episodes", str(n), NA),
        ("safe landings", safe_text, f"{pct(STUDY_SAFE_RATE)} (city-wide, its best model)"),
        ("mean reasoning rounds per safe landing", fmt(rounds_safe), f"{STUDY_ROUNDS_PER_SAFE}"),
        ("median time to touchdown", fmt(median_of(e.time_to_touchdown_s for e in eps), 1, " s"), NA),
        ("median time / kinematic lower bound", fmt(median_of(e.kinematic_ratio for e in eps), 2, " x"), NA),
        (
            "landing distance to the chosen pixel's true point (median, mean)",
            f"{fmt(median_of(e.landing_distance_m for e in eps), 2, ' m')}, "
            f"{fmt(mean_of(e.landing_distance_m for e in eps), 2, ' m')}",
            " / ".join(f"{sc} {m:.2f} m" for sc, m in sorted(STUDY_LANDING_DISTANCE_M.items())),
        ),
        (
            "companion peak RSS (max, median)",
            f"{max(rss):.0f} MB, {np.median(rss):.0f} MB" if rss else NA,
            f"{STUDY_PEAK_RSS_MB:.0f} MB (its pipeline)",
        ),
    ]
    if outcomes:
        rows.append(("outcomes", ", ".join(f"{k}: {v}" for k, v in sorted(outcomes.items())), NA))
    out = ["<h2>Summary</h2>", table(("", "this run", "reference study"), rows)]
    groups: dict[tuple[str, str, str], list[Episode]] = defaultdict(list)
    for e in eps:
        groups[(e.scenario, *e.group)].append(e)
    if len(groups) > 1:
        grows = [
            (
                *key,
                len(g),
                pct(sum(e.verdict == "safe" for e in g) / len(g)),
                fmt(mean_of(float(e.rounds) for e in g if e.verdict == "safe" and e.rounds is not None)),
                fmt(median_of(e.time_to_touchdown_s for e in g), 1, " s"),
            )
            for key, g in sorted(groups.items())
        ]
        head = ("scenario", "reasoner", "context", "episodes", "safe", "rounds / safe", "median time")
        out.append(table(head, grows))
    return "\n".join(out)


def _modules(mod: Mapping[str, Any]) -> str:
    out = []
    sid = as_mapping(mod.get("surface_id"))
    if sid:
        jaccard = _per_scenario(sid, [f"jaccard_{k}" for k in _STATS], _STATS, 3, "", STUDY_JACCARD)
        out += ["<h3>Surface ID: Jaccard index</h3>", jaccard]
    dist = as_mapping(mod.get("landing_distance"))
    if not dist:  # the short form: the mean alone
        dist = {sc: {"mean_m": m} for sc, m in as_mapping(mod.get("landing_distance_m")).items()}
    if dist:
        out += [
            "<h3>Landing distance (horizontal error at touchdown)</h3>",
            _per_scenario(dist, [f"{k}_m" for k in _STATS2], _STATS2, 2, " m", STUDY_LANDING_DISTANCE_M),
        ]
    rows = []
    for sc, by_ctx in sorted(as_mapping(mod.get("reasoner")).items()):
        for ctx, r in sorted(as_mapping(by_ctx).items()):
            r = as_mapping(r)
            rates = ("rank_success", "confirm_accept_clear", "confirm_reject_cluttered")
            latencies = ("rank_latency_s_median", "confirm_latency_s_median")
            rates_txt = [pct(as_number(r.get(k))) for k in rates]
            lat_txt = [fmt(as_number(r.get(k)), 3, " s") for k in latencies]
            rows.append((sc, ctx, *rates_txt, fmt(as_number(r.get("iterations")), 0), *lat_txt))
    if rows:
        head = ("scenario", "context", "rank success", "confirm: accepts clear", "confirm: rejects cluttered",
                "runs", "rank latency (median)", "confirm latency (median)")  # fmt: skip
        out += ["<h3>Reasoner stage success per context level</h3>", table(head, rows)]
    return "\n".join(["<h2>Modules</h2>", *out]) if out else ""


def _per_scenario(
    by_scenario: Mapping[str, Any],
    keys: Sequence[str],
    heads: Sequence[str],
    digits: int,
    unit: str,
    study: Mapping[str, float],
) -> str:
    """Statistics ``keys`` (columns ``heads``) per scenario, with the runs and the study's figure."""
    rows = []
    for sc, r in sorted(by_scenario.items()):
        r = as_mapping(r)
        theirs = as_number(r.get("study"))
        theirs = study.get(sc) if theirs is None else theirs
        stats = (fmt(as_number(r.get(k)), digits, unit) for k in keys)
        rows.append((sc, *stats, fmt(as_number(r.get("iterations")), 0), fmt(theirs, digits, unit)))
    return table(("scenario", *heads, "runs", "study"), rows)


def _landings(
    eps: list[Episode], config: Mapping[str, Any], fig_dir: Path, basemaps: Mapping[str, BaseMap]
) -> str:
    out = ["<h2>Landings</h2>"]
    if not eps:
        return out[0] + '<p class="note">No episodes in this run.</p>'
    by_world: dict[tuple[str, int], list[Episode]] = defaultdict(list)
    for e in eps:  # a map per world: a city per city seed
        by_world[(e.scenario, e.city_seed if e.city_seed is not None else -1)].append(e)
    several = len({s for s, _ in by_world}) < len(by_world)
    used: set[str] = set()
    for (scenario, city), group in sorted(by_world.items()):
        title = f"{scenario}, city seed {city}" if city >= 0 and several else scenario
        name = unique_name(f"map_{slug(title)}.png", used)
        bm = None if several else basemaps.get(scenario)
        notes = map_figure(scenario, group, config if not several else {}, bm, fig_dir / name)
        out += [f"<h3>{escape(title)}</h3>", img_tag(name, f"bird's-eye map of {title}"), *notes]
    surface_figure(eps, fig_dir / "surfaces.png")
    rounds_figure(eps, fig_dir / "rounds.png")
    out += [
        "<h3>Touchdown surfaces</h3>",
        img_tag("surfaces.png", "touchdown surface shares"),
        "<h3>Reasoning rounds</h3>",
        img_tag("rounds.png", "histogram of reasoning rounds"),
    ]
    return "\n".join(out)


def _failures(eps: list[Episode], config: Mapping[str, Any], fig_dir: Path) -> str:
    """Every episode that did not end in a safe landing, by failure class (grading.failure_class),
    each with what it did and a thumbnail of its touchdown site over the world's ground truth."""
    by: dict[str, list[Episode]] = defaultdict(list)
    for e in eps:
        if e.failure is not None:
            by[e.failure].append(e)
    out = ["<h2>Failures by class</h2>"]
    if not by:
        return out[0] + f'<p class="note">None: {len(eps)} of {len(eps)} episodes landed safely.</p>'
    out.append(table(("class", "episodes", "share"), [
        (cls, len(g), pct(len(g) / len(eps))) for cls, g in sorted(by.items(), key=lambda kv: -len(kv[1]))
    ]))  # fmt: skip
    used: set[str] = set()
    for cls, group in sorted(by.items(), key=lambda kv: -len(kv[1])):
        out.append(f'<h3>{escape(cls)} ({len(group)})</h3><ul class="failures">')
        for e in group[:_MAX_FAILURES_SHOWN]:
            thumb = ""
            if e.touchdown_ne is not None:
                name = unique_name(f"touchdown_{slug(e.id)}.png", used)
                if thumbnail(e, config, fig_dir / name):
                    thumb = img_tag(name, f"touchdown site of {e.id}")
            what = "; ".join(e.reasons) if e.verdict == "unsafe" else (e.error or "")
            last = f" Last: {e.last_state}." if e.last_state and e.verdict == "none" else ""
            out.append(
                f"<li>{thumb}<b>#{e.number} {escape(e.id)}</b>: {escape(e.outcome)} on {escape(e.surface)} "
                "after "
                f"{e.rounds if e.rounds is not None else '?'} round(s). {escape(what)}{escape(last)}</li>"
            )
        if len(group) > _MAX_FAILURES_SHOWN:
            out.append(f"<li>... and {len(group) - _MAX_FAILURES_SHOWN} more (the episode table)</li>")
        out.append("</ul>")
    return "\n".join(out)


def _latency(eps: list[Episode]) -> str:
    lat: dict[tuple[str, str], list[float | None]] = defaultdict(list)
    for e in eps:
        for stage, tier, s in e.calls:
            lat[(stage, tier)].append(s)
    if not lat:
        return '<h2>Reasoner latency</h2><p class="note">No reasoner calls recorded.</p>'
    stage_order = {"rank": 0, "confirm": 1}
    rows = []
    for (stage, tier), xs in sorted(lat.items(), key=lambda kv: (stage_order.get(kv[0][0], 2), kv[0])):
        v = [x for x in xs if x is not None]
        p90 = float(np.percentile(v, 90)) if v else None
        rows.append((stage, tier, len(xs), fmt(median_of(v), 3, " s"), fmt(p90, 3, " s")))
    return "<h2>Reasoner latency</h2>" + table(("stage", "tier", "calls", "median", "p90"), rows)


def _weather(eps: list[Episode]) -> str:
    """Per weather; per city seed and weather as well when the run flew several cities."""
    cities = sorted({e.city_seed for e in eps if e.city_seed is not None})
    by: dict[str, list[Episode]] = defaultdict(list)
    for e in eps:
        by[e.weather].append(e)
        if len(cities) > 1:
            by[f"city {e.city_seed}, {e.weather}"].append(e)
    rows = []
    for w, g in sorted(by.items(), key=lambda kv: (kv[0].startswith("city"), kv[0])):
        safe = [e for e in g if e.verdict == "safe"]
        rows.append(
            (
                w,
                len(g),
                len(safe),
                pct(len(safe) / len(g)),
                fmt(mean_of(float(e.rounds) for e in safe if e.rounds is not None)),
                fmt(mean_of(float(e.rounds) for e in g if e.rounds is not None)),
            )
        )
    head = ("weather", "episodes", "safe", "safe rate", "mean rounds (safe landings)", "mean rounds (all)")
    return "<h2>Weather</h2>" + table(head, rows)


def _clusters(eps: list[Episode], fig_dir: Path) -> str:
    out = ["<h2>Rationale clusters</h2>"]
    items = [(stage, text) for e in eps for stage, text in e.rationales]
    if not items:
        return out[0] + '<p class="note">No rationales in this run.</p>'
    if len({t for _, t in items}) < MIN_TO_CLUSTER:
        return _rationale_list(items)
    try:
        cl = cluster_rationales([t for _, t in items])
    except EmbeddingsUnavailable as exc:
        return out[0] + f'<p class="note">Rationale clusters not drawn: {escape(exc)}</p>'
    stages = [s for s, _ in items]
    cluster_figure(cl, stages, fig_dir / "rationales.png")
    out += [
        f"<p>{len(items)} rationales from the rank and confirm stages, clustered together (k-means on "
        "all-MiniLM-L6-v2 sentence embeddings; the picture is their 2-D PCA projection; marker shape "
        "gives the stage).</p>",
        img_tag("rationales.png", "rationale clusters"),
        "<ol>",
    ]
    for c in cl.clusters:
        by_stage = Counter(s for s, lab in zip(stages, cl.labels, strict=True) if lab == c.label)
        mix = ", ".join(f"{s} {n}" for s, n in sorted(by_stage.items()))
        quotes = "".join(f"<blockquote>{escape(short(t))}</blockquote>" for t in c.representatives)
        out.append(f"<li><b>C{c.label + 1}</b>: {c.size} rationales ({escape(mix)}){quotes}</li>")
    out.append("</ol>")
    return "\n".join(out)


def _rationale_list(items: list[tuple[str, str]]) -> str:
    """A run with few distinct rationales: each one with its stages, most said first, unclustered."""
    stages: dict[str, Counter[str]] = defaultdict(Counter)  # text -> how often each stage said it
    for stage, text in items:
        stages[text][stage] += 1
    out = [
        "<h2>Rationale clusters</h2>",
        f"<p>{len(items)} rationales from the rank and confirm stages, {len(stages)} of them distinct: too "
        f"few to cluster (clusters are drawn from {MIN_TO_CLUSTER} distinct texts), so each is listed.</p>",
        "<ol>",
    ]
    for text, by_stage in sorted(stages.items(), key=lambda kv: -kv[1].total()):  # most said first
        mix = escape(", ".join(f"{s} {k}" for s, k in sorted(by_stage.items())))
        out.append(f"<li>{by_stage.total()} x ({mix})<blockquote>{escape(short(text))}</blockquote></li>")
    out.append("</ol>")
    return "\n".join(out)


def _episode_table(eps: list[Episode]) -> str:
    rows = [
        (e.number, e.id, e.scenario, *e.group, e.weather, e.outcome, e.surface,
         "yes" if e.verdict == "safe" else "no", fmt(None if e.rounds is None else float(e.rounds), 0),
         fmt(e.time_to_touchdown_s, 1, " s"), fmt(e.landing_distance_m, 2, " m"),
         "; ".join(e.reasons) + (f" (error: {e.error})" * bool(e.error))
         + (f" (last: {e.last_state})" * bool(e.verdict == "none" and e.last_state)))
        for e in eps
    ]  # fmt: skip
    head = ("#", "id", "scenario", "reasoner", "context", "weather", "outcome", "surface", "safe", "rounds",
            "time", "landing distance", "reasons")  # fmt: skip
    return (
        f"<h2>Episodes</h2><details open><summary>{len(eps)} episodes (# is the number on the maps)</summary>"
        f"{table(head, rows)}</details>"
    )
