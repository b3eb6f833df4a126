"""Surface ID Jaccard index against the ground-truth safe zones, from simbridge renders at launch.

For each curated scenario and seed (the seed moves the traffic and draws the LiDAR noise and
dropouts), one frame is rendered at the scenario's launch pose; Surface ID runs on it and the box of
its best candidate is compared with the safe zone's box projected into the image (the Jaccard index,
intersection over union). Depth sources: ``lidar`` (the default in flight) and ``file`` (the
renderer's exact depth image, as ``companion-eval surfaces --depth`` reads it). The study's figures:
0.871 (scenario1) and 0.596 (scenario2); our goal: >= 0.90 in both.

The figure in results.json comes from ``companion-bench modules`` (landfall_eval/modules.py, LiDAR depth,
20 seeds, the same ``best_jaccard``); this script adds the file-depth source beside it. It prints a table
and, with ``--json``, the figures under ``modules.surface_id.<scenario>.jaccard_mean``.

Usage: python benchmarks/eval_surface_id.py [--seeds 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

from landfall_eval.study import STUDY_JACCARD as STUDY
from landfall_eval.surfaces import best_jaccard, launch_frame

GOAL = 0.90


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--json", type=Path, help="also write the figures to this file")
    args = ap.parse_args(argv)
    out: dict[str, dict[str, object]] = {}
    print(f"Surface ID Jaccard index of the best candidate, {args.seeds} seeds per scenario")
    print(f"{'scenario':<11}{'source':<8}{'mean':>7}{'min':>7}{'max':>7}{'study':>7}  goal >= {GOAL}")
    ok = True
    for scenario, study in STUDY.items():
        frames = [launch_frame(scenario, seed) for seed in range(args.seeds)]
        entry: dict[str, object] = {"study": study}
        for source in ("lidar", "file"):
            scores = [best_jaccard(lf, source)[0] for lf in frames]
            mean = statistics.fmean(scores)
            entry[source] = {"jaccard_mean": round(mean, 4), "jaccard_min": round(min(scores), 4)}
            verdict = "met" if mean >= GOAL else "NOT met"
            ok &= source != "lidar" or mean >= GOAL
            print(
                f"{scenario:<11}{source:<8}{mean:>7.3f}{min(scores):>7.3f}{max(scores):>7.3f}"
                f"{study:>7.3f}  {verdict}"
            )
        lidar = entry["lidar"]
        assert isinstance(lidar, dict)
        entry["jaccard_mean"] = lidar["jaccard_mean"]
        out[scenario] = entry
    if args.json:
        args.json.write_text(json.dumps({"modules": {"surface_id": out}}, indent=2) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
