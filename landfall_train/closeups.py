"""Procedural close-ups of flat roofs (gravel, ballast, membrane) with and without rooftop objects.

A vehicle confirming a site looks at its roof from 10-20 m up, at 0.3-2 cm per pixel: close enough
that a gravel roof's pebbles are each several pixels wide, and the seams of a membrane roof are lines.
simbridge's renders draw those materials as textures seen from higher up, and photographs of such roofs
are not among the labelled ones, so a net taught on both can mistake pebbles for clutter or seams for
painted lane markings, and refuse a clear gravel roof. These patches show those surfaces up close with
per-pixel labels (:mod:`landfall_train.labels`): the roof surface everywhere, and where objects stand on
it (HVAC boxes with grilles, round vents, pipe runs, skylights), ``object``. They join the renders in
:mod:`landfall_train.photos` and pass through the same augmentation and targets.

Pebbles are convex polygons of one stone's tone, lit from one side (a highlight and a shadow edge);
ballast is the same, larger; membranes are a pale sheet with low-frequency mottling, welded seams and
patches. Every patch depends on (seed, index) only.
"""

from __future__ import annotations

import cv2
import numpy as np

from landfall_train.labels import CLASSES

__all__ = ["closeup", "closeups"]

ROOF = CLASSES.index("roof")
OBJECT = CLASSES.index("object")
STREAM = 515  # the close-ups' random stream
CLUTTERED_P = 0.5  # share of close-ups with objects on them


def _pebbles(px: int, rng: np.random.Generator, size: tuple[float, float]) -> np.ndarray:
    tone = rng.uniform(80.0, 185.0) * rng.uniform(0.9, 1.1, 3)
    img = np.ones((px, px, 3), np.float32) * tone * rng.uniform(0.5, 0.8)  # the gaps between stones
    n = int(1.6 * px * px / float(np.mean(size)) ** 2)
    light = rng.uniform(0, 2 * np.pi)
    dx, dy = np.cos(light), np.sin(light)
    for _ in range(n):
        cx, cy = rng.uniform(0, px, 2)
        r = rng.uniform(*size) / 2
        k = int(rng.integers(5, 9))
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        rad = r * rng.uniform(0.6, 1.0, k)
        pts = np.stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)], axis=1).astype(np.int32)
        stone = tone * rng.uniform(0.65, 1.3) + rng.normal(0, 5, 3)
        cv2.fillConvexPoly(img, pts + np.array([round(dx), round(dy)], np.int32), (stone * 0.55).tolist())
        cv2.fillConvexPoly(img, pts, stone.tolist())
        if r >= 2:
            hi = (pts - np.array([cx, cy])) * 0.45 + np.array([cx - dx * r * 0.3, cy - dy * r * 0.3])
            cv2.fillConvexPoly(img, hi.astype(np.int32), np.minimum(stone * 1.15, 255).tolist())
    return img


def _membrane(px: int, rng: np.random.Generator) -> np.ndarray:
    tone = rng.uniform(120.0, 235.0) * rng.uniform(0.95, 1.05, 3)
    mottle = cv2.GaussianBlur(rng.normal(0.0, 1.0, (px, px)).astype(np.float32), (0, 0), px / 12)
    img = tone * (1.0 + 0.08 * mottle / max(float(np.abs(mottle).max()), 1e-6))[:, :, None]
    step = int(rng.integers(px // 4, px // 2 + 1))
    for x in range(int(rng.integers(0, step)), px, step):  # welded seams, sheet overlaps
        w = int(rng.integers(1, 4))
        img[:, x : x + w] *= rng.uniform(0.8, 0.95)
    for _ in range(int(rng.integers(0, 3))):  # repair patches
        x0, y0 = (int(v) for v in rng.integers(0, px, 2))
        s = int(rng.integers(px // 10, px // 4))
        img[y0 : y0 + s, x0 : x0 + s] *= rng.uniform(0.9, 1.08)
    return np.asarray(img + rng.normal(0, 3, img.shape), np.float32)


def _objects(img: np.ndarray, lab: np.ndarray, rng: np.random.Generator) -> None:
    px = img.shape[0]
    for _ in range(int(rng.integers(1, 4))):
        kind = int(rng.integers(4))
        cx, cy = (int(v) for v in rng.integers(px // 8, px - px // 8, 2))
        shade = int(rng.integers(3, 10))
        mask = np.zeros((px, px), np.uint8)
        if kind == 0:  # an HVAC box with its grille
            w, h = (int(v) for v in rng.integers(px // 8, px // 3, 2))
            cv2.rectangle(mask, (cx - w // 2, cy - h // 2), (cx + w // 2, cy + h // 2), 1, -1)
            colour = rng.uniform(120, 220) * np.ones(3)
        elif kind == 1:  # a round vent or a turbine
            r = int(rng.integers(px // 24, px // 10))
            cv2.circle(mask, (cx, cy), r, 1, -1)
            colour = rng.uniform(60, 200) * np.ones(3)
        elif kind == 2:  # a pipe run on its supports
            x1, y1 = (int(v) for v in rng.integers(0, px, 2))
            cv2.line(mask, (cx, cy), (x1, y1), 1, int(rng.integers(3, 8)))
            colour = rng.uniform(90, 230) * rng.uniform(0.8, 1.1, 3)
        else:  # a skylight
            w, h = (int(v) for v in rng.integers(px // 10, px // 4, 2))
            cv2.rectangle(mask, (cx - w // 2, cy - h // 2), (cx + w // 2, cy + h // 2), 1, -1)
            colour = np.array([150.0, 185.0, 215.0]) * rng.uniform(0.7, 1.1)
        shadow = np.roll(mask, (shade, shade), axis=(0, 1)) & (1 - mask)
        img[shadow > 0] *= 0.5
        img[mask > 0] = colour + rng.normal(0, 6, (int(mask.sum()), 3))
        if kind == 0:  # the grille: dark slats across the box
            ys, xs = np.nonzero(mask)
            slats = (ys % 6 < 2) & (xs % 3 == 0)
            img[ys[slats], xs[slats]] *= 0.5
        lab[mask > 0] = OBJECT


def closeup(seed: int, index: int, px: int = 160) -> tuple[np.ndarray, np.ndarray]:
    """One close-up: (RGB uint8 (px, px, 3), classes uint8 (px, px))."""
    rng = np.random.default_rng([seed, STREAM, index])
    kind = rng.choice(3, p=(0.4, 0.25, 0.35))
    if kind == 0:
        img = _pebbles(px, rng, (2.0, 7.0))  # gravel at 0.5-2 cm per pixel
    elif kind == 1:
        img = _pebbles(px, rng, (6.0, 16.0))  # ballast, or gravel from very close
    else:
        img = _membrane(px, rng)
    lab = np.full((px, px), ROOF, np.uint8)
    if rng.random() < CLUTTERED_P:
        _objects(img, lab, rng)
    img = cv2.GaussianBlur(img, (0, 0), float(rng.uniform(0.4, 1.0)))
    return np.asarray(np.clip(img, 0, 255), np.uint8), lab


def closeups(seed: int, n: int, px: int = 160) -> tuple[np.ndarray, np.ndarray]:
    """``n`` close-ups stacked: images (n, px, px, 3) uint8 and classes (n, px, px) uint8."""
    pairs = [closeup(seed, i, px) for i in range(n)]
    return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])
