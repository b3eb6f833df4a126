"""``companion-eval``: run one pipeline module on files and print one JSON object (DESIGN.md section 4).

    companion-eval surfaces IMAGE [--depth D.npy [--relative]] [--lidar L.npy] [--pose N,E,ALT,YAW]
                            [--hfov DEG] [--annotated out.png]
    companion-eval rank [--reasoner NAME] [--context IMAGE] [--config FILE] [--critical] [--no-fallback]
                        IMAGE...
    companion-eval confirm [--reasoner NAME] [--config FILE] [--critical] [--no-fallback] IMAGE

``rank`` orders candidate images (index k = the k-th IMAGE) by landing safety and prints
``{"ranking": [...], "rationale": ..., "tier": ..., "latency_s": ..., "errors": [...]}``; ``confirm``
judges one close-up and prints ``{"confirm": true|false, "rationale": ..., "tier": ..., "latency_s": ...,
"errors": [...]}``. They run the flight cascade: ``--reasoner`` first (default: the config's
``reasoner.name``, else ``onboard``), the onboard tier when it cannot answer in time; ``tier`` says who
answered and ``errors`` lists the tiers that failed first (tier, kind, message). With ``--no-fallback``
only the named tier runs, and a failure prints ``{"error": {"kind", "message"}, "tier", "latency_s"}``
with exit status 3. The onboard reasoner works on any RGB image alone (no geometry: degraded mode).

``surfaces`` runs Surface ID. Depth comes from ``--lidar`` (body FRD points, as ``simbridge render
--lidar-out`` writes them; metric), else ``--depth`` (a depth image, camera z in metres as ``simbridge
render --depth-out`` writes it, or relative with ``--relative``), else the image alone through Depth
Anything V2 (the optional ``depth`` extra and local weights, ``--depth-model``). ``--pose`` places the
camera (north, east, altitude above the ground, yaw in degrees; level) so candidates carry NED sites;
without it the camera is level at an unknown place.

Exit status: 0 with an answer printed, 2 for bad input (the message says what was wrong), 3 when
``--no-fallback`` and the tier failed.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from companion.config import load_config
from companion.config_schema import ReasonerConfig
from companion.guidance.frames import PinholeCamera
from companion.perception.depth import (
    ArrayDepth,
    DepthError,
    DepthSource,
    LidarDepth,
    load_depth_file,
)
from companion.perception.sources import make_source
from companion.perception.surface_id import Candidate, SurfaceParams, propose
from companion.reasoning.base import ConfirmRequest, Decision, Ranking, RankRequest, Reasoner, ReasonerError
from companion.reasoning.cascade import Cascade
from companion.reasoning.tiers import ONBOARD, build_cascade


def _pose(text: str) -> tuple[float, float, float, float]:
    try:
        parts = [float(v) for v in text.split(",")]
    except ValueError:
        parts = []
    if len(parts) != 4 or not all(math.isfinite(v) for v in parts):
        raise argparse.ArgumentTypeError(
            f"expected N,E,ALT,YAW (metres, metres, metres, degrees), got {text!r}"
        )
    return parts[0], parts[1], parts[2], parts[3]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="companion-eval", description="Run one Landfall module on files.")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("surfaces", help="Surface ID: flat-surface candidates as JSON")
    s.add_argument("image", type=Path, help="camera image (PNG or JPEG), top = vehicle forward")
    s.add_argument("--depth", type=Path, help="depth image .npy, camera z in metres (rows x cols of IMAGE)")
    s.add_argument("--relative", action="store_true", help="--depth is relative (any scale), not metres")
    s.add_argument("--lidar", type=Path, help="LiDAR points .npy, N x 3 or N x 4, body FRD metres")
    s.add_argument("--depth-model", help="Depth Anything V2 checkpoint directory or cached Hugging Face id")
    s.add_argument("--pose", type=_pose, help="N,E,ALT,YAW of the camera (level; ALT above the ground)")
    s.add_argument("--hfov", type=float, default=90.0, help="horizontal field of view, degrees (default 90)")
    s.add_argument("--annotated", type=Path, help="also draw the candidates on the image into this file")

    def reasoner_flags(q: argparse.ArgumentParser) -> None:
        q.add_argument("--reasoner", help="first tier: onboard or an LVLM profile (default: the config's)")
        q.add_argument("--config", type=Path, help="companion TOML (profiles, deadlines, fallbacks)")
        q.add_argument("--critical", action="store_true", help="as for a critical alarm (shorter deadline)")
        q.add_argument("--no-fallback", action="store_true", help="only the named tier; exit 3 if it fails")

    r = sub.add_parser("rank", help="order candidate images by landing safety")
    r.add_argument("images", type=Path, nargs="+", metavar="IMAGE", help="candidate crops (PNG or JPEG)")
    r.add_argument("--context", type=Path, help="the whole camera view, shown as context only")
    reasoner_flags(r)
    c = sub.add_parser("confirm", help="is this close-up safe to descend onto")
    c.add_argument("image", type=Path, help="close-up of the site (PNG or JPEG)")
    reasoner_flags(c)
    return p


MAX_RANK_IMAGES = 10


def reasoner_config(reasoner: str | None, config: Path | None) -> ReasonerConfig:
    """The ``[reasoner]`` section of the companion config ``config`` (or the defaults and environment),
    with ``reasoner`` as the first tier when given. Raises ConfigError (a ValueError) on a bad config or
    an unknown reasoner name."""
    overrides = {"reasoner.name": reasoner} if reasoner else {}
    return load_config(config, os.environ, overrides).reasoner


class Asker:
    """Rank and confirm requests through one flight cascade, each answered as ``companion-eval`` prints
    it (see :meth:`ask`). An async context manager: entering builds the cascade (a ConfigError for an
    unknown tier name), leaving closes its HTTP clients; one cascade serves many requests, one at a time.

    Args:
        cfg: the reasoner config (:func:`reasoner_config`).
        no_fallback: only the first tier answers; its failure is an error answer, not a hand-over.
    """

    def __init__(self, cfg: ReasonerConfig, *, no_fallback: bool = False) -> None:
        self.cfg = cfg
        self.no_fallback = no_fallback
        self._exchanges: list[dict[str, Any]] = []
        self._cascade: Cascade | None = None

    async def __aenter__(self) -> Asker:
        self._cascade = build_cascade(self.cfg, record=lambda kind, fields: self._exchanges.append(fields))
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        if self._cascade is not None:
            cascade, self._cascade = self._cascade, None
            await cascade.aclose()

    async def ask(self, request: RankRequest | ConfirmRequest) -> tuple[dict[str, Any], int]:
        """One answer and the exit status ``companion-eval`` gives it.

        Returns:
            ``({"ranking": [...] | "confirm": bool, "rationale", "tier", "latency_s", "errors"}, 0)``, where
            ``errors`` lists the tiers that failed before the answering one (tier, kind, message) and
            ``latency_s`` is wall seconds for the whole request; with ``no_fallback`` and a failed tier,
            ``({"error": {"kind", "message"}, "tier", "latency_s"}, 3)``.
        """
        cascade = self._cascade
        if cascade is None:
            raise RuntimeError("Asker.ask outside its async with block")
        self._exchanges.clear()  # this request's exchanges only (one request at a time)
        t0 = time.perf_counter()
        if self.no_fallback:
            stage = "rank" if isinstance(request, RankRequest) else "confirm"
            tiers = cascade.rank_tiers if stage == "rank" else cascade.confirm_tiers
            tier: Reasoner = tiers[0] if self.cfg.name != ONBOARD else cascade.onboard
            deadline = time.monotonic() + cascade.deadline_s(stage, request.critical)
            try:
                async with asyncio.timeout(deadline - time.monotonic()):
                    answer: Ranking | Decision = await (
                        tier.rank(replace(request, deadline=deadline))
                        if isinstance(request, RankRequest)
                        else tier.confirm(replace(request, deadline=deadline))
                    )
            except (ReasonerError, TimeoutError) as exc:
                kind = exc.kind if isinstance(exc, ReasonerError) else "deadline"
                return {
                    "error": {"kind": kind, "message": str(exc) or "stage deadline"},
                    "tier": tier.name,
                    "latency_s": round(time.perf_counter() - t0, 4),
                }, 3
        elif isinstance(request, RankRequest):
            answer = await cascade.rank(request)
        else:
            answer = await cascade.confirm(request)
        out: dict[str, Any]
        if isinstance(answer, Ranking):
            out = {"ranking": list(answer.order)}
        else:
            out = {"confirm": answer.accept}
        out.update(rationale=answer.rationale, tier=answer.tier, latency_s=round(time.perf_counter() - t0, 4))
        out["errors"] = [{"tier": e["tier"], **e["error"]} for e in self._exchanges if "error" in e]
        return out, 0


async def _ask(args: argparse.Namespace, request: RankRequest | ConfirmRequest) -> tuple[dict[str, Any], int]:
    async with Asker(reasoner_config(args.reasoner, args.config), no_fallback=args.no_fallback) as asker:
        return await asker.ask(request)


def rank(args: argparse.Namespace) -> tuple[dict[str, Any], int]:
    if len(args.images) > MAX_RANK_IMAGES:
        raise ValueError(f"at most {MAX_RANK_IMAGES} candidate images, got {len(args.images)}")
    crops = tuple(read_rgb(p) for p in args.images)
    context = read_rgb(args.context) if args.context is not None else None
    return asyncio.run(_ask(args, RankRequest(crops, None, context=context, critical=args.critical)))


def confirm(args: argparse.Namespace) -> tuple[dict[str, Any], int]:
    return asyncio.run(_ask(args, ConfirmRequest(read_rgb(args.image), None, critical=args.critical)))


def read_rgb(path: Path) -> np.ndarray:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise DepthError(f"{path}: not a readable image (PNG or JPEG)")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def draw_candidates(image_rgb: np.ndarray, cands: Sequence[Candidate]) -> np.ndarray:
    """The image (BGR, for writing) with every box, its index and score; the best in green."""
    out = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR)
    for c in reversed(cands):
        colour = (160, 160, 160) if c.fallback else (0, 220, 0) if c.index == 0 else (0, 200, 255)
        x0, y0, x1, y1 = c.box_px
        cv2.rectangle(out, (x0, y0), (x1 - 1, y1 - 1), colour, 2)
        u, v = (round(x) for x in c.centre_px)
        cv2.drawMarker(out, (u, v), colour, cv2.MARKER_CROSS, 14, 2)
        label = f"{c.index}" if c.fallback else f"{c.index}: {c.score:.0f}"
        cv2.putText(out, label, (x0 + 4, y0 + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 3)
        cv2.putText(out, label, (x0 + 4, y0 + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.55, colour, 1)
    return out


def surfaces(args: argparse.Namespace) -> dict[str, Any]:
    image = read_rgb(args.image)
    h, w = image.shape[:2]
    camera = PinholeCamera.from_hfov(w, h, args.hfov)
    lidar = None
    source: DepthSource
    if args.lidar is not None:
        lidar = load_depth_file(args.lidar)
        source = LidarDepth()
    elif args.depth is not None:
        source = ArrayDepth(load_depth_file(args.depth), metric=not args.relative)
    else:
        source = make_source("depth-anything", model=args.depth_model)
    pos = quat = ground = None
    if args.pose is not None:
        n, e, alt, yaw = args.pose
        pos, ground = (n, e, -alt), -alt
        quat = (math.cos(math.radians(yaw) / 2), 0.0, 0.0, math.sin(math.radians(yaw) / 2))
    t0 = time.perf_counter()
    cands, depth = propose(
        source,
        camera,
        image=image,
        lidar_frd=lidar,
        quat_wxyz=quat or (1.0, 0.0, 0.0, 0.0),
        pos_ned_m=pos,
        ground_up_m=ground,
        params=SurfaceParams(),
    )
    latency = time.perf_counter() - t0
    if args.annotated is not None:
        args.annotated.parent.mkdir(parents=True, exist_ok=True)
        if not cv2.imwrite(str(args.annotated), draw_candidates(image, cands)):
            raise DepthError(f"--annotated: cannot write an image to {args.annotated} (use .png or .jpg)")
    return {
        "image": str(args.image),
        "size": [w, h],
        "depth_source": depth.source,
        "metric": depth.metric,
        "fallback": all(c.fallback for c in cands),
        "boxes": [list(c.box_px) for c in cands],
        "candidates": [c.to_json() for c in cands],
        "latency_s": round(latency, 4),
    }


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "surfaces":
            result, status = surfaces(args), 0
        else:
            result, status = (rank if args.command == "rank" else confirm)(args)
    except (DepthError, ValueError) as exc:  # ConfigError is a ValueError
        print(f"companion-eval {args.command}: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(result))
    return status


if __name__ == "__main__":
    sys.exit(main())
