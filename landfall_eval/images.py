"""``companion-bench images``: a reasoning tier's image judgement on a folder of labelled photographs.

The folder has the layout of ``../shared/realimages``: ``labels.json``, a list of entries
``{"file": "images/x.jpg", "label": "clear_roof" | "cluttered_roof" | "not_roof", "land": true | false |
null, ...}`` (``null``: either answer is right), and the images it names. Two kinds of case:

- **confirm**: each image alone, as ``companion-eval confirm --reasoner NAME IMAGE`` asks it (image only,
  no LiDAR check). Every image is asked; the cases are the images whose ``land`` is not null, and one is
  right when the answer equals ``land``.
- **rank**: every (clear_roof, cluttered_roof) pair in both orders, the two images as the two candidate
  crops of one rank request (no geometry, as ``companion-eval rank IMG1 IMG2``); right when the clear
  roof comes first. With context ``full`` the request also carries, as its context image, the two side
  by side at a common height (a photograph has no wider frame to show).

Requests go one at a time through one flight cascade (:class:`companion.eval_cli.Asker`), so a remote
tier that fails hands over to the onboard tier as in flight; ``summary.tiers`` says who answered.
:func:`run_images` writes ``OUT/results.json`` (schema ``landfall-bench-images/1``, docs/bench.md) and
``OUT/report.html`` (summary tables, every miss with thumbnails embedded as base64 JPEG). Bad input is
a :class:`LabelsError` that names the entry, raised before anything is written.
"""

from __future__ import annotations

import asyncio
import json
import os
import sys
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np
from tqdm import tqdm

from companion.config import ConfigError
from companion.eval_cli import Asker, reasoner_config
from companion.reasoning.base import ConfirmRequest, RankRequest
from companion.reasoning.lvlm import encode_image
from landfall_eval.report.markup import PAGE, escape, fmt, header, pct, table

__all__ = [
    "CONTEXTS",
    "LABELS",
    "SCHEMA",
    "Ask",
    "LabelledImage",
    "LabelsError",
    "evaluate",
    "load_folder",
    "rank_pairs",
    "run_images",
    "save_results",
    "side_by_side",
    "write_images_report",
]

SCHEMA = "landfall-bench-images/1"
LABELS = ("clear_roof", "cluttered_roof", "not_roof")
CONTEXTS = ("crop", "full")
LABELS_FILE = "labels.json"
RESULTS = "results.json"
THUMB_PX = 240  # the report's thumbnails: longer side, pixels
_GAP_PX = 8  # white gap between the two images of a side-by-side context


class LabelsError(ValueError):
    """A labelled folder that cannot be evaluated; the message names the entry and says what was expected.

    Attributes:
        entry: the 1-based position of the faulty entry in labels.json, or None for the folder or file.
        file: the entry's ``file`` when it has a usable one.
    """

    def __init__(self, message: str, entry: int | None = None, file: str | None = None) -> None:
        super().__init__(message)
        self.entry = entry
        self.file = file


class Ask(Protocol):
    """What :func:`evaluate` needs of :class:`companion.eval_cli.Asker`: one answer per request, as
    ``companion-eval`` prints it, and its exit status."""

    async def ask(self, request: RankRequest | ConfirmRequest) -> tuple[dict[str, Any], int]: ...


@dataclass(frozen=True, slots=True)
class LabelledImage:
    """One labels.json entry with its pixels (H x W x 3 uint8 RGB)."""

    entry: int  # 1-based position in labels.json
    file: str  # as written in labels.json, relative to the folder
    label: str  # one of LABELS
    land: bool | None  # the right confirm answer; None: either is right
    what: str
    rgb: np.ndarray = field(repr=False, compare=False)
    source: str = ""  # labels.json's source_repo, where given: the figures per source


# ------------------------------------------------------------------------------------------ reading
def load_folder(folder: Path) -> list[LabelledImage]:
    """Every entry of ``folder/labels.json`` with its image, in file order.

    Raises:
        LabelsError: the folder or labels.json is missing or not a JSON list; an entry is not an object,
            lacks ``file``, ``label`` or ``land``, has a label not in LABELS or a ``land`` that is not
            true, false or null, names a file twice, or names a file that is missing or not a readable
            image.
    """
    if not folder.is_dir():
        raise LabelsError(f"{folder}: no such folder (expected a folder with {LABELS_FILE} and its images)")
    path = folder / LABELS_FILE
    if not path.is_file():
        raise LabelsError(f"{folder}: no {LABELS_FILE} in it (expected a list of file, label, land entries)")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise LabelsError(f"{path}: cannot be read ({exc})") from exc
    except json.JSONDecodeError as exc:
        raise LabelsError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(data, list):
        raise LabelsError(f"{path}: expected a list of entries, got a JSON {_json_kind(data)}")
    images: list[LabelledImage] = []
    seen: dict[str, int] = {}
    for entry, raw in enumerate(data, 1):
        image = _entry(folder, entry, raw)
        if image.file in seen:
            raise LabelsError(
                f"{LABELS_FILE} entry {entry} ({image.file}): the same file as entry {seen[image.file]}",
                entry,
                image.file,
            )
        seen[image.file] = entry
        images.append(image)
    return images


def _entry(folder: Path, entry: int, raw: object) -> LabelledImage:
    where = f"{LABELS_FILE} entry {entry}"
    if not isinstance(raw, dict):
        raise LabelsError(
            f"{where}: expected an object with file, label and land, got {_json_kind(raw)}", entry
        )
    if "file" not in raw:
        raise LabelsError(
            f"{where}: no 'file' (expected the image's path in the folder, e.g. images/x.jpg)", entry
        )
    file = raw["file"]
    if not isinstance(file, str) or not file.strip() or Path(file).is_absolute():
        raise LabelsError(
            f"{where}: 'file' must be a path relative to the folder, got {json.dumps(file)}", entry
        )
    where = f"{where} ({file})"
    if "label" not in raw:
        raise LabelsError(f"{where}: no 'label' (expected one of {', '.join(LABELS)})", entry, file)
    label = raw["label"]
    if label not in LABELS:
        raise LabelsError(f"{where}: label {label!r} is not one of {', '.join(LABELS)}", entry, file)
    if "land" not in raw:
        raise LabelsError(f"{where}: no 'land' (expected true, false or null)", entry, file)
    land = raw["land"]
    if not (land is None or isinstance(land, bool)):
        raise LabelsError(f"{where}: land {json.dumps(land)} is not true, false or null", entry, file)
    path = folder / file
    if not path.is_file():
        raise LabelsError(f"{where}: no such file {path}", entry, file)
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise LabelsError(f"{where}: {path} is not a readable image (PNG or JPEG)", entry, file)
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB) if bgr.ndim == 3 and bgr.shape[2] == 3 else bgr
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8 or rgb.size == 0:
        raise LabelsError(
            f"{where}: {path} is not a 3-channel 8-bit image once read (got {rgb.shape} {rgb.dtype})",
            entry,
            file,
        )
    what, source = raw.get("what"), raw.get("source_repo")
    return LabelledImage(
        entry, file, str(label), land, what if isinstance(what, str) else "", rgb,
        source if isinstance(source, str) else "",
    )  # fmt: skip


def _json_kind(x: object) -> str:
    kinds = {dict: "object", list: "list", str: "string", bool: "boolean", type(None): "null"}
    return kinds.get(type(x), "number")


# ------------------------------------------------------------------------------------------ cases
def rank_pairs(images: Sequence[LabelledImage]) -> list[tuple[LabelledImage, LabelledImage]]:
    """The rank cases as (first crop, second crop): each clear roof with each cluttered one, both orders."""
    clear = [i for i in images if i.label == "clear_roof"]
    cluttered = [i for i in images if i.label == "cluttered_roof"]
    return [pair for c in clear for k in cluttered for pair in ((c, k), (k, c))]


def side_by_side(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a`` and ``b`` (RGB) scaled to the lower of their heights and joined left to right with a white
    gap: the context image of a ``full`` rank case."""
    h = min(a.shape[0], b.shape[0])

    def scaled(x: np.ndarray) -> np.ndarray:
        if x.shape[0] == h:
            return x
        w = max(1, round(x.shape[1] * h / x.shape[0]))
        return cv2.resize(x, (w, h), interpolation=cv2.INTER_AREA)

    gap = np.full((h, _GAP_PX, 3), 255, np.uint8)
    return np.hstack([scaled(a), gap, scaled(b)])


async def evaluate(
    images: Sequence[LabelledImage],
    asker: Ask,
    *,
    context: str = "crop",
    progress: Callable[[int, int, int, int], None] | None = None,
) -> dict[str, Any]:
    """Ask every confirm and rank case through ``asker`` (entered); the results' figures.

    Args:
        images: the folder's entries (:func:`load_folder`).
        asker: an entered :class:`Asker` (or a stand-in), asked one request at a time.
        context: ``crop`` (the two images alone) or ``full`` (also side by side as context).
        progress: called after each request with (confirm correct, confirm cases, rank correct, rank
            cases) so far.

    Returns:
        The ``summary``, ``by_label``, ``latency_s``, ``images`` and ``rank_misses`` of results.json.
    """
    if context not in CONTEXTS:
        raise ValueError(f"context must be one of {', '.join(CONTEXTS)}, got {context!r}")
    records: list[dict[str, Any]] = []
    tiers: dict[str, Counter[str]] = {"confirm": Counter(), "rank": Counter()}
    latency: dict[str, list[float]] = {"confirm": [], "rank": []}
    tally = {"confirm": [0, 0], "rank": [0, 0]}  # correct, cases

    def tick() -> None:
        if progress is not None:
            progress(*tally["confirm"], *tally["rank"])

    for img in images:
        out, _ = await asker.ask(ConfirmRequest(img.rgb, None))
        answer = out.get("confirm")
        correct = None if img.land is None else answer == img.land
        if correct is not None:
            tally["confirm"][0] += correct
            tally["confirm"][1] += 1
        tiers["confirm"][str(out.get("tier"))] += 1
        latency["confirm"].append(float(out["latency_s"]))
        records.append({
            "file": img.file, "label": img.label, "land": img.land, "what": img.what, "source": img.source,
            "confirm": answer, "correct": correct, "rationale": _rationale(out), "tier": out.get("tier"),
            "latency_s": out["latency_s"], "rank_cases": 0, "rank_correct": 0,
        })  # fmt: skip
        tick()
    by_file = {r["file"]: r for r in records}
    misses: list[dict[str, Any]] = []
    for first, second in rank_pairs(images):
        ctx = side_by_side(first.rgb, second.rgb) if context == "full" else None
        out, _ = await asker.ask(RankRequest((first.rgb, second.rgb), None, context=ctx))
        ranking = [k for k in out.get("ranking") or [] if isinstance(k, int)]
        clear = 0 if first.label == "clear_roof" else 1
        right = bool(ranking) and ranking[0] == clear
        tally["rank"][0] += right
        tally["rank"][1] += 1
        tiers["rank"][str(out.get("tier"))] += 1
        latency["rank"].append(float(out["latency_s"]))
        for img in (first, second):
            by_file[img.file]["rank_cases"] += 1
            by_file[img.file]["rank_correct"] += right
        if not right:
            misses.append({
                "files": [first.file, second.file], "clear": (first, second)[clear].file, "ranking": ranking,
                "rationale": _rationale(out), "tier": out.get("tier"), "latency_s": out["latency_s"],
            })  # fmt: skip
        tick()
    by_label: dict[str, dict[str, Any]] = {label: {"cases": 0, "correct": 0} for label in LABELS}
    for r in records:
        if r["correct"] is not None:
            by_label[r["label"]]["cases"] += 1
            by_label[r["label"]]["correct"] += r["correct"]
    for v in by_label.values():
        v["accuracy"] = _fraction(v["correct"], v["cases"])
    (c_ok, c_n), (r_ok, r_n) = tally["confirm"], tally["rank"]
    by_source = {
        source: _errors([r for r in records if r["source"] == source])
        for source in sorted({r["source"] for r in records})
    }
    return {
        "summary": {
            "confirm_accuracy": _fraction(c_ok, c_n), "rank_accuracy": _fraction(r_ok, r_n),
            "confirm_cases": c_n, "rank_cases": r_n, "confirm_correct": c_ok, "rank_correct": r_ok,
            **{k: v for k, v in _errors(records).items() if k not in _CASE_KEYS},
            "tiers": {stage: dict(sorted(c.items())) for stage, c in tiers.items()},
        },
        "by_label": by_label,
        "by_source": by_source,
        "latency_s": {stage: _stats(v) for stage, v in latency.items()},
        "images": records,
        "rank_misses": misses,
    }  # fmt: skip


_CASE_KEYS = ("confirm_cases", "confirm_correct", "rank_cases", "rank_correct")


def _errors(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Confirm cases and right answers of ``records``, the false accepts (answered "land" on an image
    labelled ``land: false``) and false refusals (anything else on one labelled ``land: true``) with
    their rates, and the rank cases the images took part in and those ranked right (a pair counts for
    both of its images)."""
    unsafe = [r for r in records if r["land"] is False]
    safe = [r for r in records if r["land"] is True]
    false_accepts = sum(r["confirm"] is True for r in unsafe)
    false_refusals = sum(r["confirm"] is not True for r in safe)
    return {
        "confirm_cases": len(safe) + len(unsafe),
        "confirm_correct": sum(r["correct"] is True for r in records),
        "rank_cases": sum(r["rank_cases"] for r in records),
        "rank_correct": sum(r["rank_correct"] for r in records),
        "false_accepts": false_accepts, "unsafe_cases": len(unsafe),
        "false_accept_rate": _fraction(false_accepts, len(unsafe)),
        "false_refusals": false_refusals, "safe_cases": len(safe),
        "false_refuse_rate": _fraction(false_refusals, len(safe)),
    }  # fmt: skip


def _rationale(out: Mapping[str, Any]) -> str:
    if "rationale" in out:
        return str(out["rationale"])
    err = out.get("error") or {}  # a failed tier without fallback: say why there is no answer
    return f"no answer: {err.get('kind')}: {err.get('message')}"


def _fraction(correct: int, cases: int) -> float | None:
    return None if cases == 0 else correct / cases


def _stats(xs: Sequence[float]) -> dict[str, float | None]:
    if not xs:
        return {"median": None, "p90": None, "max": None}
    v = np.asarray(xs, dtype=float)
    return {
        "median": round(float(np.median(v)), 4),
        "p90": round(float(np.percentile(v, 90)), 4),
        "max": round(float(v.max()), 4),
    }


# ------------------------------------------------------------------------------------------ the command
def run_images(
    folder: Path,
    out: Path,
    *,
    reasoner: str | None = None,
    config: Path | None = None,
    context: str = "crop",
    quiet: bool = False,
    command: str = "images",
) -> int:
    """``companion-bench images``: evaluate, write ``out/results.json`` then ``out/report.html``.

    Returns the exit status: 0 done; 2 bad input (the message on stderr names what was wrong; nothing
    is written); 4 the report could not be written (results.json is).
    """
    t0 = time.monotonic()
    try:
        cfg = reasoner_config(reasoner, config)
        images = load_folder(folder)
        _check_out(out)
    except (OSError, ValueError) as exc:  # LabelsError and ConfigError are ValueErrors
        print(f"companion-bench images: {exc}", file=sys.stderr)
        return 2
    pairs = len(rank_pairs(images))
    bar = tqdm(total=len(images) + pairs, unit="case", disable=quiet, file=sys.stderr, dynamic_ncols=True)

    def progress(c_ok: int, c_n: int, r_ok: int, r_n: int) -> None:
        bar.set_postfix_str(f"confirm {c_ok}/{c_n}, rank {r_ok}/{r_n}", refresh=False)
        bar.update(1)

    async def ask_all() -> dict[str, Any]:
        async with Asker(cfg) as asker:
            return await evaluate(images, asker, context=context, progress=progress)

    try:
        figures = asyncio.run(ask_all())
    except ConfigError as exc:  # an unknown tier name, found when the cascade is built
        print(f"companion-bench images: {exc}", file=sys.stderr)
        return 2
    finally:
        bar.close()
    results: dict[str, Any] = {
        "schema": SCHEMA,
        "command": command,
        "created_unix_s": round(time.time(), 3),
        "config": {
            "dir": str(folder),
            "reasoner": reasoner,
            "context": context,
            "config": str(config) if config is not None else None,
        },
        **figures,
        "wall_s": round(time.monotonic() - t0, 2),
    }
    out.mkdir(parents=True, exist_ok=True)
    save_results(out, results)
    s = results["summary"]
    print(
        f"confirm {s['confirm_correct']}/{s['confirm_cases']} ({pct(s['confirm_accuracy'])}), "
        f"rank {s['rank_correct']}/{s['rank_cases']} ({pct(s['rank_accuracy'])}); "
        f"false accepts {s['false_accepts']}/{s['unsafe_cases']} ({pct(s['false_accept_rate'])}), "
        f"false refusals {s['false_refusals']}/{s['safe_cases']} ({pct(s['false_refuse_rate'])}); "
        f"results: {out / RESULTS} ({results['wall_s']:.0f} s)",
        file=sys.stderr,
    )
    try:
        page = write_images_report(results, out, folder)
    except Exception as exc:  # the page is a convenience: results.json is what counts
        print(f"companion-bench images: the report could not be written: {exc}", file=sys.stderr)
        return 4
    print(f"report:  {page}", file=sys.stderr)
    return 0


def _check_out(out: Path) -> None:
    """Refuse to replace another command's results.json in ``out``."""
    path = out / RESULTS
    if not path.exists():
        return
    try:
        schema = json.loads(path.read_text()).get("schema")
    except (ValueError, AttributeError):
        schema = None
    if schema != SCHEMA:
        raise ValueError(f"{path} is not a companion-bench images results file; choose another --out")


def save_results(out: Path, results: Mapping[str, Any]) -> None:
    """Write results.json atomically (a crash leaves the old file or the new one, never half of one)."""
    tmp = out / f".{RESULTS}.tmp"
    tmp.write_text(json.dumps(results, indent=1) + "\n")
    os.replace(tmp, out / RESULTS)


# ------------------------------------------------------------------------------------------ report
def write_images_report(results: Mapping[str, Any], out_dir: Path, folder: Path) -> Path:
    """Write ``out_dir/report.html``: the summary tables, then every confirm miss and every rank-miss
    pair with thumbnails of the images in ``folder`` (base64 JPEG, longer side <= THUMB_PX, made now
    from the user's files; an image that cannot be read any more shows as a note). Returns its path."""
    thumbs: dict[str, str] = {}

    def thumb(file: str) -> str:
        if file not in thumbs:
            bgr = cv2.imread(str(folder / file), cv2.IMREAD_COLOR)
            if bgr is None:
                thumbs[file] = f'<span class="note">({escape(file)}: not readable now)</span>'
            else:
                url, (w, h) = encode_image(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), THUMB_PX, 80)
                thumbs[file] = f'<img src="{url}" width="{w}" height="{h}" alt="{escape(file)}">'
        return thumbs[file]

    config = results.get("config") or {}
    s = results.get("summary") or {}
    lat = results.get("latency_s") or {}
    by_label = results.get("by_label") or {}
    parts = [header(results, config), "<h2>Summary</h2>"]
    parts.append(table(("stage", "cases", "correct", "accuracy", "median latency", "p90", "max"), [
        (stage, s.get(f"{stage}_cases"), s.get(f"{stage}_correct"), pct(s.get(f"{stage}_accuracy")),
         *(_seconds((lat.get(stage) or {}).get(k)) for k in ("median", "p90", "max")))
        for stage in ("confirm", "rank")
    ]))  # fmt: skip
    parts.append(table(("confirm: safety", "said", "of", "rate"), [
        ("false accepts (land on a site labelled unsafe)", s.get("false_accepts"), s.get("unsafe_cases"),
         pct(s.get("false_accept_rate"))),
        ("false refusals (refuse a site labelled safe)", s.get("false_refusals"), s.get("safe_cases"),
         pct(s.get("false_refuse_rate"))),
    ]))  # fmt: skip
    by_source = results.get("by_source") or {}
    if len(by_source) > 1:
        parts.append(table(("source", "confirm right", "false accepts", "false refusals", "rank right*"), [
            (source or "(none given)", f"{v['confirm_correct']}/{v['confirm_cases']}",
             f"{v['false_accepts']}/{v['unsafe_cases']}", f"{v['false_refusals']}/{v['safe_cases']}",
             f"{v['rank_correct']}/{v['rank_cases']}")
            for source, v in by_source.items()
        ]))  # fmt: skip
        parts.append("<p>* the rank cases an image of that source took part in.</p>")
    parts.append(table(("label (confirm)", "cases", "correct", "accuracy"), [
        (label, v.get("cases"), v.get("correct"), pct(v.get("accuracy"))) for label, v in by_label.items()
    ]))  # fmt: skip
    tiers = s.get("tiers") or {}
    parts.append(table(("stage", "answered by", "requests"), [
        (stage, tier, n) for stage, counts in tiers.items() for tier, n in counts.items()
    ]))  # fmt: skip
    misses = [r for r in results.get("images") or [] if r.get("correct") is False]
    parts.append(f"<h2>Confirm misses ({len(misses)})</h2>")
    for r in misses:
        text = (
            f"<b>{escape(r['file'])}</b> ({escape(r['label'])}: {escape(r.get('what', ''))})<br>"
            f"expected {_yes(r['land'], 'either')}, answered {_yes(r['confirm'], 'nothing')} "
            f"({escape(r.get('tier'))})"
            f"<blockquote>{escape(r.get('rationale', ''))}</blockquote>"
        )
        parts.append(_row([thumb(r["file"])], text))
    rank_misses = results.get("rank_misses") or []
    pairs: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for m in rank_misses:
        other = m["files"][1] if m["files"][0] == m["clear"] else m["files"][0]
        pairs.setdefault((m["clear"], other), []).append(m)
    parts.append(f"<h2>Rank misses ({len(rank_misses)} cases, {len(pairs)} pairs)</h2>")
    parts.append(
        '<p class="note">Left: the clear roof, which should come first; right: the cluttered one.</p>'
    )
    for (clear, other), ms in pairs.items():
        text = f"<b>{escape(clear)}</b> (clear) vs <b>{escape(other)}</b> (cluttered)" + "".join(
            f"<br>sent {'clear first' if m['files'][0] == clear else 'cluttered first'}, ranking "
            f"{escape(m.get('ranking'))} ({escape(m.get('tier'))})"
            f"<blockquote>{escape(m.get('rationale', ''))}</blockquote>"
            for m in ms
        )
        parts.append(_row([thumb(clear), thumb(other)], text))
    page = PAGE.format(
        title=escape(f"companion-bench: {results.get('command', 'images')}"), body="\n".join(parts)
    )
    path = out_dir / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def _row(pictures: Sequence[str], text: str) -> str:
    return (
        '<div style="display:flex;gap:1em;align-items:flex-start;margin-bottom:1em">'
        f"{''.join(f'<div>{p}</div>' for p in pictures)}<div style='max-width:36em'>{text}</div></div>"
    )


def _yes(x: object, none: str) -> str:
    return "yes" if x is True else "no" if x is False else none


def _seconds(x: object) -> str:
    return fmt(x if isinstance(x, int | float) else None, 3, " s")
