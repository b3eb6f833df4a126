"""Image-space randomisation of a labelled patch, and the training targets of what comes out.

Rendered patches are too clean and too alike: one texture per material, one sensor, hard shadows.
:func:`augment` (numpy + OpenCV, seeded by the caller's generator) cuts a ``size`` square out of a patch
with a random scale (``SCALE``), rotation and flip, then varies what a real camera and a real roof vary:

- colour: per-channel gain (white balance), gamma, brightness and contrast, saturation; a hue shift
  (now and then any hue) on roof, object and ground pixels only (water's blue and vegetation's green
  carry meaning); sometimes a blue or grey cast over the whole image (flat grey roofs must not read as
  water); water itself now and then turns murky (``MURKY_P``: the green, brown or slate of ponds, rivers
  and flooded pits, which are rarely the renderer's clear blue);
- overlays that keep the labels: soft shadow polygons, low-frequency stains on roof pixels (moss, rust,
  dirt); now and then a foreign texture over the roof or the ground (ridges, rows with joints or
  blotches at any angle, period and contrast: ``TEXTURE_SWAP_P``), so the net learns that a roof is a
  roof by its shape and what stands on it, not by the renderer's few textures;
- degradation: Gaussian or motion blur, a 2x down-and-up (a kite camera's softness), noise, vignetting,
  JPEG compression.

:func:`targets` turns a class map into what LandNet-S learns: per stride-8 cell, which classes are
present (at least ``CELL_MIN_PX`` pixels, or ``CELL_MIN_SHARE`` of the cell), and whether the whole
patch is a clear landing site (:func:`landfall_train.labels.site_clear`).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from landfall_train.labels import CLASSES, CLEAR_ROOF_SHARE, IGNORE, site_clear

__all__ = ["CELL_PX", "augment", "targets"]

CELL_PX = 8  # LandNet-S predicts presence per cell of this many pixels a side
CELL_MIN_PX = 2
CELL_MIN_SHARE = 0.03
SCALE = (0.7, 1.4)  # output pixels per patch pixel, log-uniform
TEXTURE_SWAP_P = 0.2  # chance of a foreign texture over one roof or ground region (Tobin et al. 2017)
MURKY_P = 0.35  # chance that the water of a patch is tinted toward one of MURKY_WATER
MURKY_WATER = np.array(
    [[0.22, 0.30, 0.16], [0.33, 0.29, 0.19], [0.18, 0.21, 0.22], [0.28, 0.33, 0.26]], np.float32
)  # algae green, silty brown, dark slate, grey-green (RGB)
_WATER = 5
_SWAPPABLE = (0, 0, 10)  # roof twice as often as ground
_HUE_FREE = np.zeros(256, bool)
_HUE_FREE[[0, 1, 2, 10]] = True  # roof, object, edge, ground: any colour is plausible


def augment(
    rgb: np.ndarray, labels: np.ndarray, rng: np.random.Generator, size: int = 128
) -> tuple[np.ndarray, np.ndarray]:
    """A randomised ``size`` x ``size`` view of a patch: (RGB uint8 (size, size, 3), classes (size, size))."""
    img, lab = _geometry(rgb, labels, rng, size)
    x = img.astype(np.float32) * np.float32(1.0 / 255.0)
    x = _colour(x, lab, rng)
    x = _overlays(x, lab, rng)
    return _degrade(x, rng), lab


def targets(
    labels: np.ndarray, roof_share: float = CLEAR_ROOF_SHARE, classes: int = len(CLASSES)
) -> tuple[np.ndarray, np.ndarray, float]:
    """Cell presence (K, H/8, W/8) float32 0/1 (K ``classes``), cell validity (H/8, W/8) float32 (not
    all sky), and site_clear (1.0 or 0.0, at least ``roof_share`` roof) of a class map whose sides are
    multiples of ``CELL_PX``."""
    h, w = labels.shape
    gh, gw = h // CELL_PX, w // CELL_PX
    cut = labels[: gh * CELL_PX, : gw * CELL_PX].reshape(gh, CELL_PX, gw, CELL_PX).transpose(0, 2, 1, 3)
    blocks = cut.reshape(gh, gw, CELL_PX * CELL_PX)
    k = classes
    counts = np.stack([(blocks == c).sum(axis=2) for c in range(k)])
    need = max(CELL_MIN_PX, CELL_MIN_SHARE * CELL_PX * CELL_PX)
    presence = (counts >= need).astype(np.float32)
    valid = ((blocks != IGNORE).sum(axis=2) > 0).astype(np.float32)
    return presence, valid, float(site_clear(labels, roof_share))


def _geometry(
    rgb: np.ndarray, labels: np.ndarray, rng: np.random.Generator, size: int
) -> tuple[np.ndarray, np.ndarray]:
    h, w = labels.shape
    scale = math.exp(rng.uniform(math.log(SCALE[0]), math.log(SCALE[1])))
    angle = float(rng.uniform(0.0, 360.0))
    src = size / scale  # side of the source square
    reach = 0.5 * src * (abs(math.cos(math.radians(angle))) + abs(math.sin(math.radians(angle))))
    cx = float(rng.uniform(min(reach, w / 2), max(w - reach, w / 2)))
    cy = float(rng.uniform(min(reach, h / 2), max(h - reach, h / 2)))
    m = cv2.getRotationMatrix2D((cx, cy), angle, scale)
    m[0, 2] += size / 2 - cx
    m[1, 2] += size / 2 - cy
    border = cv2.BORDER_REFLECT_101  # a mirrored world beyond the patch: image and labels agree
    interp = cv2.INTER_AREA if scale < 1.0 else cv2.INTER_LINEAR
    src_img = cv2.GaussianBlur(rgb, (0, 0), 0.5 / scale) if scale < 0.85 else rgb
    img = cv2.warpAffine(src_img, m, (size, size), flags=interp, borderMode=border)
    lab = cv2.warpAffine(labels, m, (size, size), flags=cv2.INTER_NEAREST, borderMode=border)
    if rng.random() < 0.5:
        img, lab = img[:, ::-1], lab[:, ::-1]
    return np.ascontiguousarray(img), np.ascontiguousarray(lab)


def _colour(x: np.ndarray, lab: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    x = x * rng.uniform(0.85, 1.15, 3).astype(np.float32)  # white balance
    x = np.clip(x, 0.0, 1.0) ** np.float32(math.exp(rng.uniform(math.log(0.7), math.log(1.4))))
    mean = x.mean()
    x = (x - mean) * np.float32(rng.uniform(0.75, 1.25)) + mean * np.float32(rng.uniform(0.75, 1.25))
    grey = x.mean(axis=2, keepdims=True)
    x = grey + (x - grey) * np.float32(rng.uniform(0.5, 1.5))  # saturation
    x = np.clip(x, 0.0, 1.0)
    if rng.random() < 0.5:  # hue, where colour carries no meaning: any hue, now and then
        free = _HUE_FREE[lab]
        if free.any():
            turn = float(rng.uniform(-0.5, 0.5) if rng.random() < 0.3 else rng.uniform(-0.1, 0.1))
            hsv = cv2.cvtColor(x, cv2.COLOR_RGB2HSV)  # float: H in degrees
            hsv[..., 0][free] = (hsv[..., 0][free] + turn * 360.0) % 360.0
            x = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    if rng.random() < MURKY_P:  # murky water: what a pond or a river looks like more often than not
        water = (lab == _WATER)[..., None]
        if water.any():
            tint = MURKY_WATER[int(rng.integers(len(MURKY_WATER)))] * np.float32(rng.uniform(0.7, 1.3))
            depth = np.float32(rng.uniform(0.4, 0.9))
            x = np.where(water, x * (1.0 - depth) + tint * depth, x).astype(np.float32)
    if rng.random() < 0.2:  # a cast over everything: bluish (shade, overcast) or grey (haze)
        cast = np.array([0.55, 0.62, 0.75] if rng.random() < 0.5 else [0.6, 0.6, 0.6], np.float32)
        x = x * np.float32(1.0 - (a := float(rng.uniform(0.1, 0.3)))) + cast * np.float32(a)
    return x.astype(np.float32)


def _overlays(x: np.ndarray, lab: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    h, w = lab.shape
    if rng.random() < 0.3:  # a soft shadow polygon (a tree's or a building's beyond the view)
        pts = rng.uniform(-0.2, 1.2, (int(rng.integers(3, 7)), 2)) * np.array([w, h])
        poly = np.zeros((h, w), np.float32)
        cv2.fillPoly(poly, [cv2.convexHull(pts.astype(np.int32))], 1.0)
        mask = np.asarray(cv2.GaussianBlur(poly, (0, 0), float(rng.uniform(1.0, 6.0))), np.float32)
        x = x * (1.0 - mask[..., None] * np.float32(1.0 - rng.uniform(0.4, 0.75)))
    if rng.random() < 0.3:  # stains on the roof: low-frequency tone and hue changes
        roof = (lab == 0).astype(np.float32)
        if roof.any():
            cells = int(rng.integers(3, 9))
            coarse = rng.uniform(-1.0, 1.0, (cells, cells, 3)).astype(np.float32)
            noise = np.asarray(cv2.resize(coarse, (w, h)), np.float32)
            x = x * (1.0 + np.float32(rng.uniform(0.05, 0.2)) * noise * roof[..., None])
    if rng.random() < TEXTURE_SWAP_P:  # a foreign texture on the roof or the ground (shape, not texture)
        k = int(rng.choice(_SWAPPABLE))
        region = (lab == k).astype(np.float32)
        if region.any():
            x = x * (1.0 + _foreign_texture(h, w, rng) * region[..., None])
    return np.asarray(np.clip(x, 0.0, 1.0), np.float32)


def _foreign_texture(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    """(h, w, 1) float32 relative tone change: ridges or rows at any angle and period (sheets, tiles,
    seams, furrows), or blotches (stains, patched surfaces), of random contrast."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    contrast = np.float32(rng.uniform(0.08, 0.35))
    if rng.random() < 0.6:
        angle = float(rng.uniform(0.0, math.pi))
        period = float(rng.uniform(2.0, 14.0))  # pixels
        phase = (xx * math.cos(angle) + yy * math.sin(angle)) * np.float32(2.0 * math.pi / period)
        wave = np.sin(phase)
        if rng.random() < 0.5:  # rows with dark joints, not a smooth ridge
            wave = np.where(wave > float(rng.uniform(0.6, 0.9)), -1.0, 0.3).astype(np.float32)
        tone = wave
    else:
        cells = int(rng.integers(4, 24))
        coarse = rng.uniform(-1.0, 1.0, (cells, cells)).astype(np.float32)
        tone = np.asarray(cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC), np.float32)
    return np.asarray((contrast * tone)[..., None], np.float32)


def _degrade(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    h, w = x.shape[:2]
    if rng.random() < 0.2:  # a soft lens: down by 2 and back up
        x = cv2.resize(cv2.resize(x, (w // 2, h // 2), interpolation=cv2.INTER_AREA), (w, h))
    if rng.random() < 0.4:
        x = cv2.GaussianBlur(x, (0, 0), float(rng.uniform(0.3, 1.5)))
    if rng.random() < 0.15:  # motion blur along a random direction
        n = int(rng.integers(2, 6))
        line = np.zeros((n, n), np.float32)
        line[n // 2, :] = 1.0 / n
        rot = cv2.getRotationMatrix2D(((n - 1) / 2, (n - 1) / 2), float(rng.uniform(0, 180)), 1.0)
        kernel = np.asarray(cv2.warpAffine(line, rot, (n, n)), np.float32)
        x = cv2.filter2D(x, -1, kernel / max(float(kernel.sum()), 1e-6))
    if rng.random() < 0.5:
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((xx - w / 2) / (w / 2)) ** 2 + ((yy - h / 2) / (h / 2)) ** 2
        x = x * (1.0 - np.float32(rng.uniform(0.0, 0.3)) * r2 / 2.0)[..., None]
    x = x + rng.normal(0.0, rng.uniform(0.0, 0.03), x.shape).astype(np.float32)
    img = np.clip(x * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if rng.random() < 0.5:
        quality = int(rng.integers(30, 96))
        ok, buf = cv2.imencode(
            ".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality]
        )
        decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR) if ok else None
        if decoded is not None:
            img = np.asarray(cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB), np.uint8)
    return np.ascontiguousarray(img)
