"""The labelled photographs :mod:`landfall_train.photos` fine-tunes on (and :mod:`landfall_train.folds`,
:mod:`landfall_train.pretrained` read): the folders in the layout of ../shared/realimages, each
photograph's source (its repository, or the place an OpenAerialMap tile shows), which of them may be learnt
from (:func:`trainable`, :func:`split`), and their randomised views (:func:`photo_view`).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from landfall_train.train import INPUT_PX

__all__ = [
    "HOLD_OUT",
    "PHOTO_DIRS",
    "Photo",
    "load_photos",
    "photo_view",
    "photo_view_middle",
    "photos_or_exit",
    "read_rgb",
    "roof_surfaces",
    "split",
    "trainable",
]

PHOTO_DIRS = (Path("../shared/realimages-train"), Path("../shared/realimages"))
HOLD_OUT = ("Philippines",)
NOT_FOR_TRAINING = re.compile(r"non-commercial|research use", re.IGNORECASE)
PLACES = re.compile(r"\b(Kampala|Kathmandu|Zanzibar|Philippines)\b")
MIDDLE_INSET = 0.25  # a clear photograph's middle (each side's quarter left out) holds no hazard
SURFACE_INSET = 0.15  # a clear roof's photograph without this share of each side is its surface


@dataclass(frozen=True)
class Photo:
    path: Path
    label: str
    land: bool | None
    source: str
    licence: str


def trainable(photo: Photo) -> bool:
    """Whether the photograph's licence allows shipping weights trained on it: not one naming
    non-commercial or research-only use (:mod:`landfall_train.photos`' docstring)."""
    return not NOT_FOR_TRAINING.search(photo.licence)


def load_photos(dirs: Sequence[Path]) -> list[Photo]:
    """Every labelled photograph of ``dirs`` (the layout of ../shared/realimages), with its source.

    Raises:
        FileNotFoundError: a folder without labels.json.
    """
    out = []
    for d in dirs:
        labels = json.loads((d / "labels.json").read_text())
        prov_path = d / "provenance.json"
        prov = {p["file"]: p for p in json.loads(prov_path.read_text())} if prov_path.is_file() else {}
        for e in labels:
            repo = str(e.get("source_repo", d.name))
            place = PLACES.search(str(prov.get(e["file"], {}).get("imagery", "")))
            source = place.group(1) if place and repo == "hotosm/fAIr-utilities" else repo.split("/")[-1]
            out.append(Photo(d / e["file"], e["label"], e["land"], source, str(e.get("license", ""))))
    return out


def photos_or_exit(dirs: Sequence[Path]) -> list[Photo]:
    """:func:`load_photos` for a command: SystemExit saying what could not be read and where the
    photographs are expected."""
    try:
        return load_photos(dirs)
    except (OSError, ValueError, KeyError) as exc:
        raise SystemExit(
            f"cannot read the photographs: {exc} (../shared/realimages* beside the repository)"
        ) from None


def read_rgb(path: Path) -> np.ndarray:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"{path}: not an image OpenCV can read")
    return np.ascontiguousarray(bgr[:, :, ::-1])


def photo_view(rgb: np.ndarray, rng: np.random.Generator, px: int = INPUT_PX) -> np.ndarray:
    """One randomised ``px`` x ``px`` view of a photograph, uint8 RGB: a random crop of 45-100 % of the
    area, a quarter turn and a mirror image, colour, contrast and brightness jitter, sometimes blur or
    sensor noise."""
    return photo_view_middle(rgb, rng, px)[0]


def photo_view_middle(
    rgb: np.ndarray, rng: np.random.Generator, px: int = INPUT_PX
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`photo_view` and where in it the photograph's middle lies: a ``px`` x ``px`` bool mask of
    the view's pixels inside the photograph's middle (:data:`MIDDLE_INSET` of each side left out), moved
    with the view (crop, quarter turn, mirror image). The same random draws as :func:`photo_view`."""
    h, w = rgb.shape[:2]
    s = math.sqrt(rng.uniform(0.45, 1.0))
    ch, cw = max(8, int(h * s)), max(8, int(w * s))
    y, x = int(rng.integers(0, h - ch + 1)), int(rng.integers(0, w - cw + 1))
    interp = cv2.INTER_AREA if ch > px else cv2.INTER_LINEAR
    img: np.ndarray = np.asarray(
        cv2.resize(rgb[y : y + ch, x : x + cw], (px, px), interpolation=interp), np.float32
    )
    rows = y + (np.arange(px) + 0.5) * ch / px  # each view pixel's place in the photograph
    cols = x + (np.arange(px) + 0.5) * cw / px
    middle = ((rows > MIDDLE_INSET * h) & (rows < (1 - MIDDLE_INSET) * h))[:, None] & (
        (cols > MIDDLE_INSET * w) & (cols < (1 - MIDDLE_INSET) * w)
    )[None, :]
    turns = int(rng.integers(4))
    img, middle = np.rot90(img, turns), np.rot90(middle, turns)
    if rng.random() < 0.5:
        img, middle = img[:, ::-1], middle[:, ::-1]
    grey = img.mean(axis=2, keepdims=True)
    img = grey + (img - grey) * rng.uniform(0.6, 1.4)
    img = img * rng.uniform(0.7, 1.3) * rng.uniform(0.9, 1.1, size=3) + rng.uniform(-25.0, 25.0)
    if rng.random() < 0.3:
        img = cv2.GaussianBlur(np.ascontiguousarray(img), (0, 0), rng.uniform(0.3, 1.2))
    if rng.random() < 0.3:
        img = img + rng.normal(0.0, rng.uniform(2.0, 8.0), img.shape)
    return np.asarray(np.clip(img, 0, 255), np.uint8), np.ascontiguousarray(middle)


def split(photos: Sequence[Photo], hold_out: Sequence[str]) -> tuple[list[Photo], list[Photo]]:
    """(learnt from, held out): held out are the ``hold_out`` sources and every photograph whose licence
    bars training (:func:`trainable`)."""
    learn = [p for p in photos if trainable(p) and p.source not in hold_out]
    return learn, [p for p in photos if p not in learn]


def roof_surfaces(photos: Sequence[Photo], images: dict[Path, np.ndarray]) -> list[np.ndarray]:
    """Every photograph of a clear roof in ``photos`` without its margins (:data:`SURFACE_INSET` of each
    side, where a neighbour's foliage or a gutter may show): real roof surfaces, float32 RGB 0-1, for
    :func:`with_real_roof`."""
    out = []
    for p in photos:
        if p.label != "clear_roof" or not p.land:
            continue
        rgb = images[p.path]
        h, w = rgb.shape[:2]
        y0, x0 = int(SURFACE_INSET * h), int(SURFACE_INSET * w)
        out.append(np.ascontiguousarray(rgb[y0 : h - y0, x0 : w - x0], np.float32) / np.float32(255.0))
    return out
