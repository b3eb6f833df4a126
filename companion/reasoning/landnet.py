"""LandNet-S, the onboard tier's learned eyes: what one RGB image shows, and where.

A small fully convolutional net (``landfall_train/net.py`` defines and trains it) says, per cell of 8 x 8
pixels of its input, which classes are present (``roof``, ``object``, ``edge``, ``person``, ``vehicle``,
``water``, ``low_vegetation``, ``tree``, ``road``, ``marking``, ``ground``), and how likely the whole image
is a clear landing site (roof surface with nothing on it). It runs from an ONNX file through ONNX
Runtime on one thread (``backend="onnxruntime"``, the default where it is installed: 2.6 times faster
than OpenCV's DNN module on this net) or through OpenCV's DNN module (``backend="opencv"``, the fallback
when ONNX Runtime is missing); no torch. Both give the same outputs within 1e-5. The packaged model
may be an ensemble (``landfall_train.ensemble``: several trained nets in one graph, their logits
averaged); nothing here depends on it. The file's sidecar (``MODEL.json``) names the classes, the
input normalisation, the thresholds (calibrated on held-out simbridge renders only) and the ONNX
file's sha256, which :meth:`LandNet.load` checks.

:meth:`LandNet.read` takes an RGB uint8 image of any size (H, W, 3), scales it so the shorter side is
``short_side_px`` (the longer at most ``max_long_side_px``), both sides multiples of 16, reads it as the
sidecar's ``input.views`` says (1: as it is; 2: it and its left-right mirror image; 4: it and its three
mirror images, left-right, up-down and both; in one batch, each answer flipped back and the probabilities
averaged: a nadir view has no preferred side, and the average of several readings is steadier on imagery
unlike the renders it learnt from; :func:`view_batch` and :func:`average_views`, which calibration uses
too). Ranks read their crops with ``input.rank_views`` (default: ``views``): a rank reads five crops where
a confirmation reads one image, and only orders them, which two views do nearly as well as four on the
held-out renders. A confirmation reads its site window with the shorter side at
``input.confirm_short_side_px`` and a rank its crops at ``input.rank_short_side_px`` (both default to
``short_side_px``; 96 and 144 for the packaged model): chosen on real photographs by source-split
cross-validation (docs/reasoning.md, "Reading a confirmation smaller"). :meth:`LandNet.read` returns a
:class:`SceneReading`: the clear-site probability, the probability that nothing stands on the surface
(``bare``: a third output of sidecar format ``landfall-landnet/2``, a head trained on roof-dominated
renders by ``landfall_train.bare``; ranks weigh it), the hazard peak (the highest probability of an
object, person, vehicle, water or marking in any cell), per class the share of the image's cells where it
is present and where (a 3 x 3 compass: "upper left" ... "centre" ... "lower right"), and how many separate
groups of cells hold objects, people or vehicles. A model whose sidecar has ``rank_cells`` (LandNet-E's
second cell head, learnt from every kind of place and from high up: ``landfall_train.cells_head``) gives
a second cell output, ``cells_rank``, with thresholds of its own: ranks (:meth:`LandNet.read_rank`) and
the search's reading of its frames (:meth:`LandNet.presence`) use it, confirmations the first. One
``cv2.dnn.Net`` is not safe to call from two threads at once (the onboard tier runs in worker threads): a
lock guards either runtime.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from companion.reasoning.image_cues import check_rgb

__all__ = [
    "BACKENDS", "BARE", "DEFAULT_MODEL", "OUTPUTS", "PACKAGED", "RANK_CELLS", "VIEWS", "LandNet",
    "LandNetError", "SceneReading", "average_views", "model_outputs", "model_path", "onnx_runner",
    "rank_hazard", "view_batch", "whole_batch",
]  # fmt: skip

_log = logging.getLogger(__name__)
BACKENDS = ("auto", "onnxruntime", "opencv")
Runner = Callable[[np.ndarray], tuple[np.ndarray, ...]]  # NCHW float32 -> the outputs' logits, in order
OUTPUTS = ("cells", "clear")  # every model's outputs; a landfall-landnet/2 model adds BARE
# a model whose sidecar has ``rank_cells`` adds a second cell output that ranks and the search's camera
# read, from the search's height (LandNet-E's second cell head, landfall_train.cells_head)
RANK_CELLS = "cells_rank"
BARE = "bare"  # (N, 1, 1, 1) logit: nothing (no object, person, vehicle, water, marking) on the surface
WHOLE = "whole"  # (N, 1) logit of a whole-image read (sidecar whole_read; landfall_train.whole_read)

MODELS = Path(__file__).with_name("models")
# The packaged models by name (``reasoner.onboard_model``); any other value is the path of an ONNX file
# with its sidecar. LandNet-E (EfficientNet-Lite0's ImageNet backbone fine-tuned, with its whole-image
# read and its rank cells; ``make model``) is the default: on real photographs it confirms no unsafe
# surface where LandNet-S confirms 3-7 % of them. LandNet-S (a small net trained from nothing on
# simbridge's renders and a few photographs; ``make model-s``) is about three times as fast
# (docs/reasoning.md).
PACKAGED = {"landnet-s": MODELS / "landnet-s.onnx", "landnet-e": MODELS / "landnet-e.onnx"}
DEFAULT_MODEL = PACKAGED["landnet-e"]
HAZARD_SCALE = 3.0  # rank: hazard points of a surely-not-clear site (the image cues' water weight)
# rank, a model with the bare head (landfall-landnet/2; the packaged model has none): weight of the
# clear-site probability in a site's hazard, the rest on the probability that nothing stands on it.
# Chosen on the held-out renders for landfall_train.bare's default head (docs/reasoning.md, "A head for
# the rank's own question"): the weight that orders roof-dominated patches (no hazard against some) best
# without ordering all patches by clear site worse than the model without the head did.
RANK_BARE_CLEAR_WEIGHT = 0.25
# rank, a model without it (landfall-landnet/1): weight of the clear-site probability, the rest on the
# hazard peak (the most likely object, person, vehicle, water or marking cell), chosen the same way.
RANK_CLEAR_WEIGHT = 0.5
COUNTED = ("object", "person", "vehicle")  # classes counted as separate groups of cells
SAID_SHARE = 0.005  # the least share of another class a reading's words name
_INPUT_KEYS = ("mean", "std", "multiple", "short_side_px", "max_long_side_px")
VIEWS = (1, 2, 4)  # sidecar input.views: the image alone, with its left-right mirror, with all three
_PLACES = (
    ("upper left", "top", "upper right"),
    ("left", "centre", "right"),
    ("lower left", "bottom", "lower right"),
)
_WORDS = {
    "roof": "roof surface",
    "object": "objects on the surface",
    "edge": "edges or walls",
    "person": "people",
    "vehicle": "vehicles",
    "water": "water",
    "low_vegetation": "grass",
    "tree": "trees",
    "road": "road surface",
    "marking": "painted lane markings",
    "ground": "paving or bare ground",
}


def whole_batch(rgb: np.ndarray, side: int, views: int, mean: Any, std: Any) -> np.ndarray:
    """(views, 3, side, side) float32: an RGB uint8 image squeezed whole to a ``side`` square,
    normalised by ``mean`` / ``std`` and read in ``views`` views (:func:`view_batch`): what a whole-image
    read sees, at training (``landfall_train.whole_read``) and on the vehicle alike."""
    x = cv2.resize(rgb, (side, side), interpolation=cv2.INTER_AREA).astype(np.float32) / np.float32(255)
    chw = ((x - np.asarray(mean, np.float32)) / np.asarray(std, np.float32)).transpose(2, 0, 1)
    return np.ascontiguousarray(view_batch(chw, views), np.float32)


def view_batch(chw: np.ndarray, views: int) -> np.ndarray:
    """(views, C, H, W): an image (C, H, W) and, for 2 views, its left-right mirror image; for 4, its
    left-right, up-down and two-way mirror images."""
    if views == 1:
        return np.ascontiguousarray(chw[None])
    if views == 2:
        return np.ascontiguousarray(np.stack([chw, chw[:, :, ::-1]]))
    return np.ascontiguousarray(np.stack([chw, chw[:, :, ::-1], chw[:, ::-1, :], chw[:, ::-1, ::-1]]))


def average_views(cells_p: np.ndarray, clear_p: np.ndarray, views: int) -> tuple[np.ndarray, np.ndarray]:
    """Per image, the mean of its ``views`` readings, each cell map flipped back first.

    ``cells_p`` (N * views, K, h, w) and ``clear_p`` (N * views,) probabilities, the views of one image
    consecutive (as :func:`view_batch` makes them); returns (N, K, h, w) and (N,).
    """
    n = len(clear_p) // views
    c = cells_p.reshape(n, views, *cells_p.shape[1:])
    if views == 2:
        c = np.stack([c[:, 0], c[:, 1, :, :, ::-1]], axis=1)
    elif views == 4:
        c = np.stack([c[:, 0], c[:, 1, :, :, ::-1], c[:, 2, :, ::-1, :], c[:, 3, :, ::-1, ::-1]], axis=1)
    return c.mean(axis=1), clear_p.reshape(n, views).mean(axis=1)


class LandNetError(RuntimeError):
    """The model cannot be used: a missing, corrupt or mismatched file. ``path`` names it."""

    def __init__(self, message: str, path: Path) -> None:
        super().__init__(f"{path}: {message}")
        self.path = path


@dataclass(frozen=True, slots=True)
class SceneReading:
    """What LandNet-S saw in one image. Shares are fractions (0..1) of the image's cells."""

    model: str
    size_px: tuple[int, int]  # (height, width) of the image as given
    grid: tuple[int, int]  # (rows, cols) of cells read
    clear_p: float  # probability that the whole image is a clear landing site
    shares: tuple[tuple[str, float], ...]  # per class (sidecar order): share of cells where present
    places: tuple[tuple[str, tuple[str, ...]], ...]  # per present class: compass places, most cells first
    counts: tuple[tuple[str, int], ...]  # COUNTED classes: separate groups of cells holding them
    hazard_peak: float = 0.0  # the highest probability of a hazard class in any cell (views averaged)
    bare_p: float | None = None  # probability that nothing stands on the surface (None: no bare head)
    clear_spread: float = 0.0  # the clear-site probabilities of the views read: highest minus lowest
    # with a whole-image read (a confirmation, sidecar ``whole_read``): clear_p is the weighted mean of
    # the net's own clear-site probability (net_clear_p) and the whole read's (whole_p)
    net_clear_p: float | None = None
    whole_p: float | None = None

    @property
    def hazard(self) -> float:
        """Hazard points for a rank, on the image cues' scale. With the bare head: ``HAZARD_SCALE`` x
        (1 - (``RANK_BARE_CLEAR_WEIGHT`` x clear_p + (1 - ``RANK_BARE_CLEAR_WEIGHT``) x bare_p)); without
        it: ``HAZARD_SCALE`` x (``RANK_CLEAR_WEIGHT`` x (1 - clear_p) + (1 - ``RANK_CLEAR_WEIGHT``) x
        hazard_peak). The clear-site probability alone also falls with what surrounds a roof (a garden, a
        wall at the margin); a rank asks above all whether anything stands on it."""
        return float(rank_hazard(self.clear_p, self.hazard_peak, self.bare_p))

    def share(self, name: str) -> float:
        return dict(self.shares).get(name, 0.0)

    def where(self, name: str) -> tuple[str, ...]:
        return dict(self.places).get(name, ())

    def count(self, name: str) -> int:
        return dict(self.counts).get(name, 0)

    def phrase(self, name: str) -> str:
        """What was seen of one class, e.g. ``objects on the surface (3: upper left, centre)``."""
        places = ", ".join(self.where(name)[:3])
        if name in COUNTED:
            return f"{_WORDS[name]} ({self.count(name)}: {places})"
        return f"{_WORDS[name]} ({100 * self.share(name):.0f} %: {places})"

    def _said(self, name: str) -> bool:
        """Whether :meth:`observations` names a class: a counted one from one cell on, another from a
        share that rounds to 1 % ("0 %" would say nothing)."""
        share = self.share(name)
        return share > 0.0 if name in COUNTED else share >= SAID_SHARE

    def observations(self, names: tuple[str, ...] | None = None) -> tuple[str, ...]:
        """Phrases naming what was seen, hazards first, then the roof surface and the net's confidence."""
        order = names or ("person", "vehicle", "object", "water", "marking", "tree", "low_vegetation", "road")
        out = [self.phrase(n) for n in order if self._said(n)]
        out.append(f"roof surface {100 * self.share('roof'):.0f} %")
        if self.whole_p is not None and self.net_clear_p is not None:
            out.append(
                f"clear-site confidence {self.clear_p:.2f} [{self.model}: net {self.net_clear_p:.2f}, "
                f"whole image {self.whole_p:.2f}]"
            )
        else:
            out.append(f"clear-site confidence {self.clear_p:.2f} [{self.model}]")
        return tuple(out)

    def to_json(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "size_px": list(self.size_px),
            "grid": list(self.grid),
            "clear_p": round(self.clear_p, 4),
            "shares": {k: round(v, 4) for k, v in self.shares},
            "places": {k: list(v) for k, v in self.places},
            "counts": dict(self.counts),
            "hazard_peak": round(self.hazard_peak, 4),
            "bare_p": None if self.bare_p is None else round(self.bare_p, 4),
            "clear_spread": round(self.clear_spread, 4),
            "hazard": round(self.hazard, 3),
        } | (
            {}
            if self.whole_p is None or self.net_clear_p is None
            else {"net_clear_p": round(self.net_clear_p, 4), "whole_p": round(self.whole_p, 4)}
        )


def rank_hazard(clear_p: Any, hazard_peak: Any, bare_p: Any | None, weight: float | None = None) -> Any:
    """A rank's hazard points (:attr:`SceneReading.hazard`) of one reading or of arrays of them
    (``landfall_train.compare`` scores held-out renders with it); ``weight`` replaces the clear-site
    probability's weight (``RANK_BARE_CLEAR_WEIGHT`` or ``RANK_CLEAR_WEIGHT``) to compare others."""
    if bare_p is not None:
        w = RANK_BARE_CLEAR_WEIGHT if weight is None else weight
        return HAZARD_SCALE * (1.0 - (w * clear_p + (1.0 - w) * bare_p))
    w = RANK_CLEAR_WEIGHT if weight is None else weight
    return HAZARD_SCALE * (w * (1.0 - clear_p) + (1.0 - w) * hazard_peak)


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return np.asarray(1.0 / (1.0 + np.exp(-x.astype(np.float64))), np.float64)


def _onnxruntime_runner(onnx_path: Path, outputs: tuple[str, ...]) -> Runner:
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1  # the onboard tier's budget is one core
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3  # errors only
    # no memory arena and no memory pattern: every read has its own input size, and the arena kept the
    # largest of each (LandNet-E with its whole read: peak 214 MB in a process reading 40 random sizes,
    # 177 MB without; LandNet-S 129 MB either way; docs/reasoning.md)
    opts.enable_cpu_mem_arena = False
    opts.enable_mem_pattern = False
    session = ort.InferenceSession(str(onnx_path), opts, providers=["CPUExecutionProvider"])

    have = {o.name for o in session.get_outputs()}
    if not set(outputs) <= have:
        raise ValueError(f"the graph has outputs {sorted(have)}, not {list(outputs)}")

    def run(blob: np.ndarray) -> tuple[np.ndarray, ...]:
        return tuple(np.asarray(o) for o in session.run(list(outputs), {"image": blob}))

    return run


def _opencv_runner(onnx_path: Path, outputs: tuple[str, ...]) -> Runner:
    net = cv2.dnn.readNetFromONNX(str(onnx_path))
    have = set(net.getUnconnectedOutLayersNames())
    if not set(outputs) <= have:
        raise ValueError(f"the graph has outputs {sorted(have)}, not {list(outputs)}")

    def run(blob: np.ndarray) -> tuple[np.ndarray, ...]:
        net.setInput(blob)
        return tuple(np.asarray(o) for o in net.forward(list(outputs)))

    return run


def onnx_runner(
    onnx_path: Path, backend: str = "auto", outputs: tuple[str, ...] = OUTPUTS
) -> tuple[Runner, str]:
    """The ONNX model at ``onnx_path`` as a callable returning ``outputs`` in that order, and the
    runtime's name; LandNetError when it cannot be loaded or lacks one of ``outputs``."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        backend = "onnxruntime" if importlib.util.find_spec("onnxruntime") is not None else "opencv"
        if backend == "opencv":
            _log.info("onnxruntime is not installed: LandNet runs through OpenCV's DNN module (slower)")
    try:
        make = _onnxruntime_runner if backend == "onnxruntime" else _opencv_runner
        return make(onnx_path, tuple(outputs)), backend
    except ImportError as exc:
        raise LandNetError(f"backend {backend} is not installed: {exc}", onnx_path) from exc
    except cv2.error as exc:
        raise LandNetError(f"OpenCV cannot load the ONNX model: {exc}", onnx_path) from exc
    except ValueError as exc:
        raise LandNetError(f"the ONNX model does not give what its sidecar names: {exc}", onnx_path) from exc
    except Exception as exc:  # onnxruntime raises its own exception types for a bad graph
        raise LandNetError(f"ONNX Runtime cannot load the model: {exc}", onnx_path) from exc


class LandNet:
    """One loaded model; :meth:`read` is safe to call from several threads."""

    def __init__(
        self,
        net: Runner,
        meta: dict[str, Any],
        name: str,
        backend: str = "opencv",
        whole: Runner | None = None,
    ) -> None:
        self._net = net
        self._whole = whole
        self._lock = threading.Lock()
        self.name = name
        self.backend = backend
        self.classes: tuple[str, ...] = tuple(meta["classes"])
        inp = meta["input"]
        self.mean = np.array(inp["mean"], np.float32)
        self.std = np.array(inp["std"], np.float32)
        self.multiple = int(inp["multiple"])
        self.short_side_px = int(inp["short_side_px"])
        self.max_long_side_px = int(inp["max_long_side_px"])
        self.confirm_short_side_px = int(inp.get("confirm_short_side_px", self.short_side_px))
        self.rank_short_side_px = int(inp.get("rank_short_side_px", self.short_side_px))
        self.views = int(inp.get("views", 1))
        self.rank_views = int(inp.get("rank_views", self.views))
        thresholds = meta["thresholds"]
        self.clear_threshold = float(thresholds["clear"])
        # the net's own clear-site threshold: a rank's readings (no whole read) are described against it
        self.net_clear_threshold = float(thresholds.get("net_clear", thresholds["clear"]))
        whole_read = meta.get("whole_read") if whole is not None else None
        self.whole_side_px = int(whole_read["side_px"]) if whole_read else 0
        self.whole_views = int(whole_read["views"]) if whole_read else 0
        self.whole_weight = float(whole_read["weight"]) if whole_read else 0.0
        self.whole_mean = np.array(whole_read["mean"] if whole_read else inp["mean"], np.float32)
        self.whole_std = np.array(whole_read["std"] if whole_read else inp["std"], np.float32)
        self.cell_thresholds = np.array([float(thresholds["cells"][c]) for c in self.classes], np.float32)
        hazards = meta["hazard_classes"]
        outputs = model_outputs(meta)
        self.has_bare = BARE in outputs
        self._rank_out = outputs.index(RANK_CELLS) if RANK_CELLS in outputs else 0
        rank_cells = meta.get("rank_cells")
        self.rank_cell_thresholds = (
            np.array([float(rank_cells["thresholds"][c]) for c in self.classes], np.float32)
            if rank_cells
            else self.cell_thresholds
        )
        self._hazard_rows = np.array([k for k, c in enumerate(self.classes) if c in hazards], np.intp)

    @classmethod
    def load(cls, path: Path | str | None = None, backend: str = "auto") -> LandNet:
        """The model at ``path`` (``X.onnx`` with its sidecar ``X.json``, or a packaged model's name:
        :func:`model_path`; default: the packaged LandNet-E), run
        by ``backend`` (module docstring; ``"auto"``: ONNX Runtime where installed, else OpenCV).

        Raises:
            LandNetError: a missing or unreadable file, a sidecar without what inference needs, a sha256
                that does not match, or an ONNX file OpenCV cannot load.
        """
        onnx_path = model_path(path)
        meta_path = onnx_path.with_suffix(".json")
        for p in (onnx_path, meta_path):
            if not p.is_file():
                raise LandNetError("model file not found (make model writes it)", p)
        try:
            meta = json.loads(meta_path.read_text())
            classes, inp, thr = meta["classes"], meta["input"], meta["thresholds"]
            if not isinstance(classes, list) or not classes or set(thr["cells"]) != set(classes):
                raise ValueError("classes and cell thresholds do not match")
            if "rank_cells" in meta and set(meta["rank_cells"]["thresholds"]) != set(classes):
                raise ValueError("classes and rank_cells.thresholds do not match")
            hazards = meta["hazard_classes"]
            if not isinstance(hazards, list) or not hazards or not set(hazards) <= set(classes):
                raise ValueError(f"hazard_classes must be a non-empty list of the classes, got {hazards!r}")
            missing = [k for k in _INPUT_KEYS if k not in inp]
            if missing:
                raise ValueError(f"input lacks {', '.join(missing)}")
            for key in ("views", "rank_views"):
                if inp.get(key, 1) not in VIEWS:
                    raise ValueError(f"input.{key} must be one of {VIEWS}, got {inp.get(key)!r}")
            for key in ("confirm_short_side_px", "rank_short_side_px"):
                side = inp.get(key, inp["short_side_px"])
                if not isinstance(side, int) or isinstance(side, bool) or side < 2 * int(inp["multiple"]):
                    raise ValueError(
                        f"input.{key} must be an integer, at least twice input.multiple: {side!r}"
                    )
            float(thr["clear"])
            float(thr.get("net_clear", 0.0))
            outputs = model_outputs(meta)
            whole_path = _whole_read_path(meta.get("whole_read"), onnx_path)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise LandNetError(f"unreadable model sidecar: {exc!r}", meta_path) from exc
        _check_sha256(onnx_path, meta.get("sha256"))
        net, used = onnx_runner(onnx_path, backend, outputs)
        whole = None
        if whole_path is not None:
            if not whole_path.is_file():
                raise LandNetError("the whole read's file is missing (sidecar whole_read.file)", whole_path)
            _check_sha256(whole_path, meta["whole_read"].get("sha256"))
            whole, _used = onnx_runner(whole_path, used, (WHOLE,))
        return cls(net, meta, str(meta.get("name", onnx_path.stem)), used, whole)

    def input_size(self, h: int, w: int, short_side: int | None = None) -> tuple[int, int]:
        """(height, width) an image of ``h`` x ``w`` pixels is scaled to: the shorter side
        ``short_side`` (default: ``short_side_px``), the longer at most ``max_long_side_px`` scaled
        alike, sides multiples of ``multiple``."""
        short, long_ = min(h, w), max(h, w)
        target = short_side or self.short_side_px
        s = min(target / short, self.max_long_side_px * target / self.short_side_px / long_)
        m = self.multiple

        def side(x: int) -> int:
            return max(2 * m, m * round(x * s / m))

        return side(h), side(w)

    def read(
        self, rgb: np.ndarray, views: int | None = None, short_side: int | None = None, rank: bool = False
    ) -> SceneReading:
        """What the image shows (module docstring), read in ``views`` views (default: the sidecar's
        ``input.views``) with its shorter side scaled to ``short_side`` (default: ``short_side_px``;
        confirmations pass ``confirm_short_side_px``; ranks read through :meth:`read_rank`); ``rank``:
        the cells from the model's rank cells where it has them (``RANK_CELLS``).

        Raises:
            ValueError: not a non-empty (H, W, 3) uint8 numpy array.
        """
        img = check_rgb(rgb)
        p, clear_p, out = self._infer(img, self.views if views is None else views, short_side, rank)
        present = p[0] >= (self.rank_cell_thresholds if rank else self.cell_thresholds)[:, None, None]
        peak = float(p[0][self._hazard_rows].max())
        bare = float(_sigmoid(np.asarray(out[2]).reshape(-1)).mean()) if self.has_bare else None
        each = _sigmoid(np.asarray(out[1]).reshape(-1))
        reading = self._reading(img.shape[:2], present, float(clear_p[0]), peak, bare)
        return replace(reading, clear_spread=float(each.max() - each.min()))

    def confirmation(self, reading: SceneReading, rgb: np.ndarray) -> SceneReading:
        """``reading`` (of a confirmation's site window) with the whole-image read of ``rgb`` (the whole
        close-up) weighed into its clear-site probability (sidecar ``whole_read``); unchanged for a
        model without one.

        Raises:
            ValueError: not a non-empty (H, W, 3) uint8 numpy array.
        """
        if self._whole is None:
            return reading
        img = check_rgb(rgb)
        blob = whole_batch(img, self.whole_side_px, self.whole_views, self.whole_mean, self.whole_std)
        with self._lock:
            logits = self._whole(blob)[0]
        # the views' features were averaged when the read was fitted; the logit is linear in them
        whole_p = float(_sigmoid(np.asarray(logits).reshape(-1).mean(keepdims=True))[0])
        mixed = (1.0 - self.whole_weight) * reading.clear_p + self.whole_weight * whole_p
        return replace(reading, clear_p=mixed, net_clear_p=reading.clear_p, whole_p=whole_p)

    def read_rank(self, rgb: np.ndarray) -> SceneReading:
        """:meth:`read` as a rank reads each crop: ``rank_views`` views at ``rank_short_side_px``."""
        return self.read(rgb, self.rank_views, self.rank_short_side_px, rank=True)

    def _infer(
        self, img: np.ndarray, views: int, short_side: int | None = None, rank: bool = False
    ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
        """One image (H, W, 3) uint8 scaled (:meth:`input_size`), normalised and run in ``views`` views:
        the cells' probabilities (1, K, h, w; ``rank``: the rank cells') and the clear site's (1,), views
        averaged, and the raw outputs."""
        h, w = img.shape[:2]
        ih, iw = self.input_size(h, w, short_side)
        interp = cv2.INTER_AREA if ih * iw < h * w else cv2.INTER_LINEAR
        x = cv2.resize(img, (iw, ih), interpolation=interp).astype(np.float32) * np.float32(1.0 / 255.0)
        blob = view_batch(((x - self.mean) / self.std).transpose(2, 0, 1), views)
        with self._lock:
            out = self._net(np.ascontiguousarray(blob, np.float32))
        cells = out[self._rank_out] if rank else out[0]
        p, clear_p = average_views(_sigmoid(cells), _sigmoid(np.asarray(out[1]).reshape(-1)), views)
        return p, clear_p, out

    def probabilities(self, rgb: np.ndarray, views: int = 1) -> np.ndarray:
        """Per class (sidecar order) and cell of 8 x 8 input pixels, the probability that it is present:
        (K, h, w) float, laid out as :meth:`presence`'s cells (which are these at the cells' thresholds).

        Raises:
            ValueError: not a non-empty (H, W, 3) uint8 numpy array.
        """
        p, _clear, _out = self._infer(check_rgb(rgb), views)
        return np.asarray(p[0])

    def presence(self, rgb: np.ndarray, views: int = 1) -> np.ndarray:
        """Per class (sidecar order) and cell of 8 x 8 input pixels, whether it is present: (K, h, w)
        bool, cell (r, c) covering rows ``r * H / h`` .. and columns ``c * W / w`` .. of the image. The
        search reads its frames with it from its height, so from the rank cells where the model has them.

        Raises:
            ValueError: not a non-empty (H, W, 3) uint8 numpy array.
        """
        p, _clear, _out = self._infer(check_rgb(rgb), views, rank=True)
        return np.asarray(p[0] >= self.rank_cell_thresholds[:, None, None])

    def _reading(
        self, size: tuple[int, int], present: np.ndarray, clear_p: float, peak: float, bare: float | None
    ) -> SceneReading:
        _k, gh, gw = present.shape
        shares = tuple((c, float(present[i].mean())) for i, c in enumerate(self.classes))
        rows = np.minimum(np.arange(gh) * 3 // gh, 2)
        cols = np.minimum(np.arange(gw) * 3 // gw, 2)
        places: list[tuple[str, tuple[str, ...]]] = []
        counts: list[tuple[str, int]] = []
        for i, c in enumerate(self.classes):
            if not present[i].any():
                if c in COUNTED:
                    counts.append((c, 0))
                continue
            ys, xs = np.nonzero(present[i])
            votes = np.bincount(rows[ys] * 3 + cols[xs], minlength=9)
            order = sorted((-int(v), int(z)) for z, v in enumerate(votes) if v > 0)
            places.append((c, tuple(_PLACES[z // 3][z % 3] for _v, z in order)))
            if c in COUNTED:
                n, _ = cv2.connectedComponents(present[i].astype(np.uint8), connectivity=8)
                counts.append((c, int(n) - 1))
        return SceneReading(
            self.name, size, (gh, gw), clear_p, shares, tuple(places), tuple(counts), peak, bare
        )


def _check_sha256(path: Path, expected: object) -> None:
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if expected != digest:
        raise LandNetError(f"sha256 {digest[:12]}... does not match the sidecar's ({expected})", path)


def _whole_read_path(entry: Any, onnx_path: Path) -> Path | None:
    """The whole read's ONNX file (beside the model's) that a sidecar's ``whole_read`` names, checked;
    None without one. ValueError, KeyError or TypeError for an entry that lacks what inference needs."""
    if entry is None:
        return None
    name = str(entry["file"])
    if Path(name).name != name:
        raise ValueError(f"whole_read.file must be a file name beside the model, got {name!r}")
    if entry.get("views") not in (1, 2):
        raise ValueError(f"whole_read.views must be 1 or 2, got {entry.get('views')!r}")
    side, weight = entry["side_px"], float(entry["weight"])
    if not isinstance(side, int) or isinstance(side, bool) or side < 32:
        raise ValueError(f"whole_read.side_px must be an integer of at least 32, got {side!r}")
    if not 0.0 <= weight <= 1.0:
        raise ValueError(f"whole_read.weight must lie in 0..1, got {weight!r}")
    for key in ("mean", "std"):
        if len(entry[key]) != 3 or (key == "std" and min(entry[key]) <= 0):
            raise ValueError(f"whole_read.{key} must be three numbers (RGB), got {entry[key]!r}")
    return onnx_path.with_name(name)


def model_path(model: str | Path | None) -> Path:
    """The ONNX file ``model`` names: a packaged model's name (``PACKAGED``), a path to an ``.onnx``
    file with its sidecar beside it, or None / "" for the default (LandNet-E)."""
    if model is None or model == "":
        return DEFAULT_MODEL
    if isinstance(model, str) and model in PACKAGED:
        return PACKAGED[model]
    return Path(model)


def model_outputs(meta: dict[str, Any]) -> tuple[str, ...]:
    """The outputs a model's sidecar promises: ``OUTPUTS`` (format ``landfall-landnet/1``), and ``BARE``
    too (``landfall-landnet/2``), then ``RANK_CELLS`` where the sidecar has ``rank_cells``. ValueError for
    another format, or a /2 sidecar without ``outputs.bare``."""
    fmt = meta.get("format", "landfall-landnet/1")
    rank = (RANK_CELLS,) if "rank_cells" in meta else ()
    if fmt == "landfall-landnet/1":
        return (*OUTPUTS, *rank)
    if fmt == "landfall-landnet/2":
        if BARE not in meta.get("outputs", {}):
            raise ValueError("format landfall-landnet/2 names outputs.bare")
        return (*OUTPUTS, BARE, *rank)
    raise ValueError(f"unknown model format {fmt!r} (landfall-landnet/1 or /2)")
