"""The rounds of one landing, from its flight record, as HTML with pictures: for each ranking the
drone's-eye frame with the candidates boxed (the chosen one in green), the rationale beside it; for
each confirmation the close-up the reasoner judged and its verdict."""

from __future__ import annotations

import html
import shutil
from pathlib import Path
from typing import Any

import cv2

from companion.ground import annotated_thumbnail
from companion.record import EVENTS_FILE, read_events

FRAME_WIDTH_PX = 640


def _e(x: object) -> str:
    return html.escape(str(x))


def record_events(record_dir: Path) -> tuple[Path, list[dict[str, Any]]] | None:
    """The newest session under ``record_dir`` and its events (torn or foreign lines skipped)."""
    sessions = sorted(p.parent for p in record_dir.glob(f"*/{EVENTS_FILE}"))
    if not sessions:
        return None
    return sessions[-1], read_events(sessions[-1])


def rounds_html(record_dir: Path, fig_dir: Path) -> str:
    """The section; writes ``roundNN.jpg`` and ``roundNN-confirmK.jpg`` into ``fig_dir``."""
    out = ["<h2>Rounds</h2>"]
    found = record_events(record_dir)
    if found is None:
        return out[0] + f'<p class="note">No flight record under {_e(record_dir)}.</p>'
    session, events = found
    confirms = 0
    for ev in events:
        kind = ev.get("kind")
        if kind == "rank":
            out.append(_rank(ev, session, fig_dir))
            confirms = 0
        elif kind == "confirm":
            confirms += 1
            out.append(_confirm(ev, session, fig_dir, confirms))
        elif kind == "outcome":
            out.append(f"<p><b>Outcome</b>: {_e(ev.get('state'))} after {_e(ev.get('rounds'))} round(s) "
                       f"({_e(ev.get('reason'))})</p>")  # fmt: skip
    if len(out) == 1:
        out.append('<p class="note">The record holds no ranking.</p>')
    return "\n".join(out)


def _row(image: str, text: str) -> str:
    pic = f'<img src="figures/{_e(image)}" style="width:{FRAME_WIDTH_PX}px">' if image else ""
    return (
        '<div style="display:flex;gap:1em;align-items:flex-start;margin-bottom:1em">'
        f"<div>{pic}</div><div style='max-width:32em'>{text}</div></div>"
    )


def _rank(ev: dict[str, Any], session: Path, fig_dir: Path) -> str:
    r = int(ev.get("round", 0))
    candidates = [c for c in ev.get("candidates") or [] if isinstance(c, dict)]
    order = [k for k in ev.get("order") or [] if isinstance(k, int) and 0 <= k < len(candidates)]
    chosen = ev.get("chosen")  # the recovery's pick, recorded with the ranking
    if not (isinstance(chosen, int) and 0 <= chosen < len(candidates)):
        chosen = None
    name = ""
    frame = cv2.imread(str(session / f"round{r:02d}-acquire.jpg"))
    if frame is not None and candidates:
        rgb = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
        jpeg = annotated_thumbnail(rgb, [c["box"] for c in candidates], chosen, FRAME_WIDTH_PX, 85)
        name = f"round{r:02d}.jpg"
        (fig_dir / name).write_bytes(jpeg)
    listed = "".join(
        f"<li>{'<b>' if k == chosen else ''}candidate {k}: "
        f"{_e(_geometry(candidates[k]))}{'</b> (chosen)' if k == chosen else ''}</li>"
        for k in order
    )
    text = (
        f"<h3>Round {r}: ranking</h3><p>tier <b>{_e(ev.get('tier'))}</b>, "
        f"{_e(round(float(ev.get('latency_s') or 0.0) * 1000, 1))} ms</p>"
        f"<blockquote>{_e(ev.get('rationale', ''))}</blockquote><ol start=0>{listed}</ol>"
    )
    return _row(name, text)


def _geometry(c: dict[str, Any]) -> str:
    g = c.get("geometry") or {}
    bits = []
    if g.get("height_above_m") is not None:
        bits.append(f"{g['height_above_m']:.0f} m up")
    if g.get("landable_area_m2") is not None:
        bits.append(f"{g['landable_area_m2']:.0f} m2 landable")
    if g.get("edge_distance_m") is not None:
        bits.append(f"{g['edge_distance_m']:.1f} m from its edge")
    return ", ".join(bits) or "no geometry"


def _confirm(ev: dict[str, Any], session: Path, fig_dir: Path, k: int) -> str:
    r = int(ev.get("round", 0))
    name = ""
    src = session / str(ev.get("image") or "")
    if ev.get("image") and src.is_file():
        name = f"round{r:02d}-confirm{k}.jpg"
        shutil.copyfile(src, fig_dir / name)
    verdict = "accepted" if ev.get("accept") else "rejected"
    check = ev.get("check") or {}
    text = (
        f"<h4>Round {r}: confirmation {k}: {verdict}</h4><p>tier {_e(ev.get('tier'))}; LiDAR: "
        f"{_e(check.get('points'))} returns, {_e(check.get('roughness_m'))} m rough</p>"
        f"<blockquote>{_e(ev.get('rationale', ''))}</blockquote>"
    )
    return _row(name, text)
