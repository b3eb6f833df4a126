"""``companion-bench``: the study's experiments on simbridge, graded from ground truth, with a report.

    companion-bench modules [--iterations 20] [--reasoner NAME] --out DIR
    companion-bench curated --scenario scenario1|scenario2|river_crossing --runs N [--weather W[,W...]]
                            [--context C] [--reasoner NAME] --out DIR
    companion-bench city --seeds N [--start-index K] [--city-seeds S[,S...]] [--place KIND]
                         [--weather W[,W...]] [--context C] [--reasoner NAME] --out DIR
    ... [--executor local|ray [--ray-address ADDR] [--cpus-per-episode C]] [--resume]
    companion-bench images DIR [--context crop|full] [--reasoner NAME] --out OUT
    companion-bench compare A B          # two campaigns' safe rates: do they differ beyond chance?

Every command writes DIR/results.json (schema: docs/bench.md) and DIR/report.html with its figures.
``images`` judges a labelled photograph folder instead (landfall_eval/images.py: no simulator, its
own results schema; exit status 2 for a bad folder, naming the entry).
Episodes run in parallel (``--workers``, default: the number of cores; or as Ray tasks with
``--executor ray``: landfall_eval/campaign.py), each as its own simbridge and companion processes;
results.json is rewritten after every episode, and ``--resume`` skips the episodes DIR already holds.
Exit status: 0 done; 1 some episode could not be run (``outcome`` ``error``: a process failed, not a
landing that went wrong); 2 bad arguments; 4 the report could not be written (results.json is);
130 interrupted (what ended is in results.json: ``--resume`` goes on).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from landfall_eval.campaign import EXECUTORS, EpisodeJob, RayUnavailable, make_executor
from landfall_eval.episode import EpisodeSpec, EpisodeTimes
from landfall_eval.episode_grade import describe_last_state
from landfall_eval.grading import summarise
from landfall_eval.launches import halton_launches
from landfall_eval.usage import RunUsage, campaign_usage
from simbridge.args import non_negative_seed
from simbridge.world.places import DEFAULT_PLACE, PLACES
from simbridge.world.scenario_file import builtin_scenario_names

__all__ = ["SCHEMA", "load_results", "main", "save_results"]

SCHEMA = "landfall-bench/1"
CONTEXTS = ("crop", "pad20", "pad30", "pad40", "pad50", "pad60", "full")
WEATHERS = ("clear", "fog", "rain")
AUTOPILOTS = ("px4", "ardupilot", "ardupilot-sitl", "px4-sitl")
FIRMWARE = ("ardupilot-sitl", "px4-sitl")  # real firmware, simbridge its physics
RESULTS = "results.json"
IMAGE_CONTEXTS = ("crop", "full")  # landfall_eval.images.CONTEXTS, without importing it for every command


def load_results(out: Path) -> dict[str, Any]:
    """DIR/results.json, or a fresh skeleton. Raises ValueError on a file that is not ours."""
    path = out / RESULTS
    if not path.exists():
        return {"schema": SCHEMA, "episodes": []}
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not valid JSON ({exc}); move it away to start afresh") from None
    if not isinstance(data, dict) or data.get("schema") != SCHEMA:
        raise ValueError(f"{path} is not a companion-bench results file (schema {SCHEMA!r})")
    data.setdefault("episodes", [])
    return data


def save_results(out: Path, results: dict[str, Any]) -> None:
    """Write results.json atomically (a crash leaves the old file or the new one, never half of one)."""
    results["summary"] = summarise(results.get("episodes", []))
    tmp = out / f".{RESULTS}.tmp"
    tmp.write_text(json.dumps(results, indent=1) + "\n")
    os.replace(tmp, out / RESULTS)


def _positive(kind: type, what: str) -> Callable[[str], Any]:
    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what} must be a number, got {text!r}") from None
        if value <= 0:
            raise argparse.ArgumentTypeError(f"{what} must be > 0, got {text}")
        return value

    return parse


def _choices(what: str, known: Sequence[str]) -> Callable[[str], tuple[str, ...]]:
    """A comma-separated list of ``known`` names, each once (``clear,fog,rain``)."""

    def parse(text: str) -> tuple[str, ...]:
        got = tuple(x.strip() for x in text.split(",") if x.strip())
        bad = [x for x in got if x not in known]
        if not got or bad:
            raise argparse.ArgumentTypeError(
                f"{what}: {', '.join(bad) or 'nothing given'}: choose from {', '.join(known)}"
            )
        if len(set(got)) != len(got):
            raise argparse.ArgumentTypeError(f"{what}: {text!r} names one twice")
        return got

    return parse


def _seeds(text: str) -> tuple[int, ...]:
    """``0,1,2`` or ``0-4`` (inclusive), city seeds each once."""
    out: list[int] = []
    try:
        for part in (p.strip() for p in text.split(",") if p.strip()):
            lo, _, hi = part.partition("-")
            first, last = non_negative_seed(lo), non_negative_seed(hi or lo)
            out += range(first, last + 1)
    except (argparse.ArgumentTypeError, ValueError) as exc:
        raise argparse.ArgumentTypeError(f"--city-seeds: {exc}") from None
    if not out or len(set(out)) != len(out):
        raise argparse.ArgumentTypeError(
            f"--city-seeds: {text!r} gives {'no seed' if not out else 'a seed twice'}"
        )
    return tuple(out)


def world_cache(args: argparse.Namespace) -> Path | None:
    """The city command's place cache: ``--world-cache``, else OUT/world-cache; None for ``none``."""
    given = getattr(args, "world_cache", None)
    if given is None:
        return Path(args.out).resolve() / "world-cache"
    return None if given == "none" else Path(given).resolve()


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="companion-bench",
        description="The study's experiments on simbridge: DIR/results.json and DIR/report.html.",
    )
    sub = ap.add_subparsers(dest="command", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="results.json and report.html go here"
    )
    common.add_argument("--reasoner", default="onboard", help="first reasoning tier (default: onboard)")
    common.add_argument("--config", type=Path, help="companion TOML config (LVLM profiles, fallbacks)")
    common.add_argument("--quiet", action="store_true", help="no progress display")
    flying = argparse.ArgumentParser(add_help=False)
    flying.add_argument(
        "--weather", type=_choices("--weather", WEATHERS), default=("clear",), metavar="W[,W...]",
        help=f"one or several of {', '.join(WEATHERS)} (default clear): every episode in each",
    )  # fmt: skip
    flying.add_argument(
        "--context", choices=CONTEXTS, default="crop", help="what the reasoner sees per candidate"
    )
    flying.add_argument(
        "--autopilot", choices=AUTOPILOTS, default="px4",
        help="px4 or ardupilot: simbridge's emulation; ardupilot-sitl: real ArduCopter firmware (SITL); "
        "px4-sitl: real PX4 firmware (SITL)",
    )  # fmt: skip
    flying.add_argument(
        "--sitl", type=Path, metavar="PATH",
        help="ArduCopter SITL binary for --autopilot ardupilot-sitl "
        "(default: $LANDFALL_ARDUCOPTER, else ../shared/sitl/ardupilot/arducopter)",
    )  # fmt: skip
    flying.add_argument(
        "--px4", type=Path, metavar="PATH",
        help="PX4 SITL binary (bin/px4 of a px4_sitl_default build) for --autopilot px4-sitl "
        "(default: $LANDFALL_PX4, else ../shared/sitl/px4/bin/px4)",
    )  # fmt: skip
    _ekf_error_option(flying, "episodes (the emulation only)")
    flying.add_argument(
        "--gps-fault", type=_ne_pair, default=None, metavar="N,E",
        help="the GPS lies during each descent: its position moves N,E metres once the vehicle is below "
        "40 m above the ground (simbridge --gps-fault; any autopilot)",
    )  # fmt: skip
    flying.add_argument(
        "--gps-fault-ramp", type=float, default=0.0, metavar="S",
        help="0 (default): --gps-fault jumps at once; S > 0: it drifts there over S simulated seconds",
    )  # fmt: skip
    flying.add_argument(
        "--camera", choices=("socket", "rtp"), default="socket",
        help="where the companion's images come from: simbridge's sensor stream (socket, default) or its "
        "camera as H.264 over RTP read like a real camera, the LiDAR still on the socket (rtp; the "
        "emulated autopilots only; needs PyAV: pip install 'landfall[sim,camera]')",
    )  # fmt: skip
    flying.add_argument(
        "--workers", type=_positive(int, "--workers"), default=os.cpu_count() or 1,
        help="episodes at once (default: the number of cores)",
    )  # fmt: skip
    flying.add_argument(
        "--speed", type=_positive(float, "--speed"), default=4.0,
        help="simulation speed (simulated s per wall s; decisions do not depend on it)",
    )  # fmt: skip
    flying.add_argument(
        "--time-limit", type=_positive(float, "--time-limit"), default=600.0, metavar="SIM_S",
        help="simulated seconds after the alarm before an episode is a timeout (no landing)",
    )  # fmt: skip
    flying.add_argument(
        "--wall-limit", type=_positive(float, "--wall-limit"), metavar="WALL_S",
        help="wall seconds after the alarm before an episode is stopped as a timeout, whatever the "
        "simulation did (default: 60 + 3 x SIM_S / speed)",
    )  # fmt: skip
    flying.add_argument(
        "--resume", action="store_true",
        help="go on with the campaign in DIR: skip the episodes its results.json already holds",
    )  # fmt: skip
    flying.add_argument(
        "--retries", type=int, default=2, metavar="N",
        help="tries more for an episode that failed before its alarm (a port clash, a process that did "
        "not start); never for an outcome (default 2)",
    )  # fmt: skip
    flying.add_argument(
        "--executor", choices=EXECUTORS, default="local",
        help="local: --workers episodes at once here (default); ray: each episode a Ray task "
        "(landfall[campaign])",
    )  # fmt: skip
    flying.add_argument(
        "--launch-ahead", action=argparse.BooleanOptionalAction, default=True,
        help="local executor: each worker starts its next episode's processes, held at the start, "
        "while it flies one (default: on; the flights are the same, the starting costs no wall time)",
    )  # fmt: skip
    flying.add_argument(
        "--ray-address", metavar="ADDR",
        help="a running Ray cluster (auto, HOST:6379, ray://HOST:10001); default: a local Ray "
        "instance with --workers CPUs",
    )  # fmt: skip
    flying.add_argument(
        "--cpus-per-episode", type=_positive(float, "--cpus-per-episode"), default=1.0, metavar="C",
        help="CPUs a Ray task reserves for one episode (default 1)",
    )  # fmt: skip
    m = sub.add_parser(
        "modules", parents=[common], help="Surface ID Jaccard, IPM landing distance, stage success"
    )
    m.add_argument("--iterations", type=_positive(int, "--iterations"), default=20)
    m.add_argument("--scenario", action="append", choices=("scenario1", "scenario2"), help="default: both")
    _ekf_error_option(m, "landing flights")
    c = sub.add_parser("curated", parents=[common, flying], help="full pipeline in a curated scenario")
    c.add_argument(
        "--scenario",
        required=True,
        choices=builtin_scenario_names(),
        help="a scenario file that ships with simbridge: the study's scenario1 and scenario2, or "
        "river_crossing (a launch over a river, the roofs out of view)",
    )
    c.add_argument("--runs", type=_positive(int, "--runs"), default=10)
    y = sub.add_parser("city", parents=[common, flying], help="full pipeline from Halton launch points")
    y.add_argument("--seeds", type=_positive(int, "--seeds"), default=20, help="number of launch points")
    y.add_argument("--start-index", type=int, default=0, metavar="K", help="first Halton index (default 0)")
    cities = y.add_mutually_exclusive_group()
    cities.add_argument(
        "--city-seeds", type=_seeds, metavar="S[,S...]",
        help="seeds of the procedural cities (0,1,2 or 0-2): every launch point in each city "
        "(simbridge --city-seed); default 0",
    )  # fmt: skip
    cities.add_argument("--city-seed", type=non_negative_seed, metavar="S", help="one city: --city-seeds S")
    y.add_argument(
        "--place", choices=PLACES, default=DEFAULT_PLACE,
        help=f"the kind of place the cities are (simbridge --place; default {DEFAULT_PLACE})",
    )  # fmt: skip
    y.add_argument(
        "--world-cache", metavar="DIR|none",
        help="where each city is kept once built, for every episode and the grading to map instead of "
        "building it again (simbridge --world-cache; about 0.4 GB a downtown city); default "
        "OUT/world-cache; none: built by every process",
    )  # fmt: skip
    k = sub.add_parser("compare", help="whether two campaigns' safe rates differ beyond chance")
    k.add_argument("a", type=Path, metavar="A", help="a results.json, or the folder holding it")
    k.add_argument("b", type=Path, metavar="B", help="another")
    g = sub.add_parser(
        "images", parents=[common], help="the image judgement on a labelled folder of photographs"
    )
    g.add_argument("dir", type=Path, metavar="DIR", help="labels.json and its images (../shared/realimages)")
    g.add_argument(
        "--context", choices=IMAGE_CONTEXTS, default="crop",
        help="rank: the two images alone (crop) or also side by side as context (full)",
    )  # fmt: skip
    return ap


def _ne_pair(text: str) -> tuple[float, float]:
    try:
        n, e = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N,E metres (two numbers), got {text!r}") from None
    if not (math.isfinite(n) and math.isfinite(e)):
        raise argparse.ArgumentTypeError(f"expected two finite numbers, got {text!r}")
    return (n, e)


def _ekf_error_option(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument(
        "--ekf-error", choices=("off", "nominal"), default="off",
        help=f"{what} on the autopilot's estimate with an EKF's errors (simbridge --ekf-error)",
    )  # fmt: skip


def episode_specs(args: argparse.Namespace) -> list[EpisodeSpec]:
    """The episodes a curated or city command asks for, in order."""
    if args.sitl is not None and args.autopilot != "ardupilot-sitl":
        raise ValueError("--sitl goes with --autopilot ardupilot-sitl")
    if getattr(args, "px4", None) is not None and args.autopilot != "px4-sitl":
        raise ValueError("--px4 goes with --autopilot px4-sitl")
    if args.ekf_error != "off" and args.autopilot in FIRMWARE:
        raise ValueError("--ekf-error: real firmware has its own estimator (leave it off)")
    if args.camera == "rtp" and args.autopilot in FIRMWARE:
        raise ValueError("--camera rtp: simbridge streams its camera beside its own autopilots only")
    if args.gps_fault is None and args.gps_fault_ramp != 0.0:
        raise ValueError("--gps-fault-ramp goes with --gps-fault N,E")
    if args.gps_fault_ramp < 0:
        raise ValueError(f"--gps-fault-ramp must be >= 0 s, got {args.gps_fault_ramp}")
    base = dict(
        reasoner=args.reasoner, context=args.context, autopilot=args.autopilot, ekf_error=args.ekf_error,
        gps_fault=args.gps_fault, gps_fault_ramp_s=args.gps_fault_ramp, camera=args.camera,
    )  # fmt: skip
    if args.command == "curated":
        return [
            EpisodeSpec("curated", args.scenario, k, run=k, weather=w, **base)
            for k in range(args.runs)
            for w in args.weather
        ]
    if args.start_index < 0:
        raise ValueError(f"--start-index must be >= 0, got {args.start_index}")
    # launch by launch, each in every city and weather: a campaign cut short covers every group
    return [
        EpisodeSpec(
            "city",
            "city",
            launch.index,
            launch=launch.as_tuple(),
            launch_index=launch.index,
            city_seed=city,
            place=args.place,
            weather=w,
            **base,
        )
        for launch in halton_launches(args.seeds, args.start_index)
        for city in city_seeds(args)
        for w in args.weather
    ]


def city_seeds(args: argparse.Namespace) -> tuple[int, ...]:
    if getattr(args, "city_seeds", None):
        return tuple(args.city_seeds)
    return (args.city_seed if getattr(args, "city_seed", None) is not None else 0,)


def _line(entry: dict[str, Any]) -> str:
    verdict = "SAFE" if entry.get("safe") else "UNSAFE"
    if entry.get("outcome") != "landed":
        verdict = str(entry.get("outcome")).upper()
    last = describe_last_state(entry.get("last_state"))
    extra = f" ({entry['error']}{'; last: ' + last if last else ''})" if entry.get("error") else ""
    reasons = "; ".join(entry.get("reasons") or [])
    ttd = entry.get("time_to_touchdown_s")
    took = f", {ttd:.0f} s" if isinstance(ttd, (int, float)) else ""
    return (
        f"{entry['id']}: {verdict} on {entry.get('surface')}, {entry.get('rounds')} round(s){took}"
        f"{' - ' + reasons if reasons and not entry.get('safe') else ''}{extra}"
    )


def resolve_sitl(args: argparse.Namespace) -> Path | None:
    """The firmware binary an ``ardupilot-sitl`` or ``px4-sitl`` run flies (None for the emulation),
    found once so a missing one is a bad argument, not an error in every episode. Raises ValueError
    saying where it looked."""
    autopilot = getattr(args, "autopilot", None)
    if autopilot not in FIRMWARE:
        return None
    from simbridge.px4_sitl import find_px4
    from simbridge.sitl import SitlNotFound, find_arducopter

    try:
        return find_arducopter(args.sitl) if autopilot == "ardupilot-sitl" else find_px4(args.px4)
    except SitlNotFound as exc:
        raise ValueError(str(exc)) from None


def run_episodes(
    args: argparse.Namespace,
    results: dict[str, Any],
    specs: Sequence[EpisodeSpec],
    out: Path,
    sitl: Path | None = None,
) -> int:
    """Fly what ``results`` does not hold yet on the chosen executor, writing results.json as each
    episode ends; returns how many could not be run (``outcome`` ``error``)."""
    done = {e["id"] for e in results["episodes"]}
    todo = [s for s in specs if s.id not in done]
    skipped = len(specs) - len(todo)
    if skipped:
        print(f"resuming: {skipped} of {len(specs)} episodes already in {out / RESULTS}", file=sys.stderr)
    times = EpisodeTimes(speed=args.speed, sim_s=args.time_limit, wall_limit_s=args.wall_limit)
    cache = world_cache(args) if args.command == "city" else None
    tries = 1 + max(args.retries, 0)
    jobs = [
        EpisodeJob(s, out / "episodes" / s.id, times, args.config, sitl, tries=tries, world_cache=cache)
        for s in todo
    ]
    executor = make_executor(
        args.executor, workers=args.workers, address=args.ray_address,
        cpus_per_episode=args.cpus_per_episode, ahead=args.launch_ahead,
    )  # fmt: skip
    errors = 0
    usage, run, flown = RunUsage(local=args.executor == "local"), results["config"], 0
    bar = tqdm(
        total=len(todo), unit="episode", disable=args.quiet or not todo, file=sys.stderr, dynamic_ncols=True
    )
    try:
        for entry in executor.run(jobs):
            results["episodes"].append(entry)
            results["episodes"].sort(key=lambda e: str(e["id"]))
            flown += 1
            run["usage"] = usage.entry(flown)
            results["usage"] = campaign_usage(results["runs"])
            save_results(out, results)
            errors += entry.get("outcome") == "error"
            eps = results["episodes"]
            safe = sum(bool(e.get("safe")) for e in eps)
            bar.set_postfix_str(f"safe {safe}/{len(eps)}, errors {errors}")
            if not args.quiet:
                bar.write(_line(entry), file=sys.stderr)
            bar.update(1)
    finally:
        bar.close()
        executor.close()
    return errors


def _interrupt(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def main(argv: Sequence[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.command == "compare":
        from landfall_eval.compare import run_compare

        return run_compare(args.a, args.b)
    if args.command == "images":
        from landfall_eval.images import run_images

        return run_images(
            args.dir, args.out, reasoner=args.reasoner, config=args.config, context=args.context,
            quiet=args.quiet,
        )  # fmt: skip
    out: Path = args.out
    try:
        specs = episode_specs(args) if args.command != "modules" else []
        sitl = resolve_sitl(args)
        out.mkdir(parents=True, exist_ok=True)
        results = load_results(out)
        held = len(results["episodes"])
        if held and args.command != "modules" and not args.resume:
            raise ValueError(
                f"{out / RESULTS} already holds {held} episodes: --resume to go on with that campaign, "
                "or another --out"
            )
    except (OSError, ValueError) as exc:
        ap.error(str(exc))
    config = {
        "reasoner": args.reasoner,
        "config": str(args.config) if args.config else None,
    }
    for key in (
        "context",
        "weather",
        "autopilot",
        "ekf_error",
        "gps_fault",
        "gps_fault_ramp",
        "camera",
        "speed",
        "workers",
        "scenario",
        "runs",
        "seeds",
    ):
        if hasattr(args, key):
            config[key] = getattr(args, key)
    if args.command == "city":
        config["start_index"] = args.start_index
        config["place"] = args.place
        cache = world_cache(args)
        config["world_cache"] = str(cache) if cache is not None else None
        seeds = city_seeds(args)
        config["city_seeds"] = list(seeds)
        if len(seeds) == 1:
            config["city_seed"] = seeds[0]
    if hasattr(args, "weather"):
        config["weather"] = args.weather[0] if len(args.weather) == 1 else ",".join(args.weather)
        config["weathers"] = list(args.weather)
    if hasattr(args, "executor"):
        config["executor"] = args.executor
        config["ray_address"] = args.ray_address
        config["cpus_per_episode"] = args.cpus_per_episode
    if sitl is not None:
        config["sitl"] = str(sitl)
    results["command"] = args.command
    results["created_unix_s"] = round(time.time(), 3)
    results.setdefault("runs", []).append(config)
    results["config"] = config
    t0 = time.monotonic()
    errors = 0
    if args.command == "modules":
        from landfall_eval.modules import run_modules

        scenarios = tuple(args.scenario or ("scenario1", "scenario2"))
        bar = tqdm(total=None, disable=args.quiet, file=sys.stderr, unit="step", dynamic_ncols=True)

        def progress(text: str) -> None:
            bar.set_postfix_str(text[:80])
            bar.update(1)

        results["modules"] = run_modules(
            args.reasoner, args.iterations, scenarios=scenarios, progress=progress, config_path=args.config,
            ekf_error=args.ekf_error,
        )  # fmt: skip
        bar.close()
        save_results(out, results)
    else:
        signal.signal(signal.SIGTERM, _interrupt)  # a scheduler's stop: the same as Ctrl-C
        try:
            errors = run_episodes(args, results, specs, out, sitl)
        except RayUnavailable as exc:
            ap.error(str(exc))
        except KeyboardInterrupt:
            n = len(results["episodes"])
            print(
                f"interrupted: {n} of {len(specs)} episodes in {out / RESULTS}; the same command with "
                "--resume goes on",
                file=sys.stderr,
            )
            return 130
        save_results(out, results)
    s = results["summary"]
    if s["episodes"]:
        rate = s["safe_rate"]
        rounds = s["mean_rounds_safe"]
        print(
            f"{s['episodes']} episodes: {s['safe']} safe ({100 * rate:.0f} %), "
            f"mean rounds per safe landing {rounds if rounds is not None else '-'}, "
            f"median kinematic ratio {s['median_kinematic_ratio']}",
            file=sys.stderr,
        )
    if (u := results.get("usage")) and u["episodes_per_core_hour"]:
        print(f"{u['episodes_per_core_hour']} episodes per core-hour ({u['episodes']} episodes, "
              f"{u['core_hours']} core-hours, {u['runs']} run(s))", file=sys.stderr)  # fmt: skip
    print(f"results: {out / RESULTS} ({time.monotonic() - t0:.0f} s)", file=sys.stderr)
    try:
        from landfall_eval.report import write_report

        html = write_report(results, out)
    except Exception as exc:  # the figures are a convenience: results.json is what counts
        print(f"companion-bench: the report could not be written: {exc}", file=sys.stderr)
        return 4
    print(f"report:  {html}", file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
