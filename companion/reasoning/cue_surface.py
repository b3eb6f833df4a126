"""The surface side of the image cues (steps 2, 3, 5, 7 and 8 of :mod:`companion.reasoning.image_cues`):
the colour of the surface under each pixel, shadows, water and vegetation regions, the site region of a
close-up, edges and grain; and the connected-component tools the objects (:mod:`companion.reasoning.
cue_objects`) use too. Masks are boolean arrays of the working image's shape.
"""

from __future__ import annotations

import cv2
import numpy as np

from companion.reasoning.cue_params import CueParams

K3 = np.ones((3, 3), np.uint8)


def near(mask: np.ndarray, px: int = 2) -> np.ndarray:
    """``mask`` widened by ``px`` pixels."""
    out: np.ndarray = cv2.dilate(mask.view(np.uint8), K3, iterations=px).view(bool)
    return out


def large(mask: np.ndarray, min_share: float) -> np.ndarray:
    """The components of ``mask`` of at least ``min_share`` of the image."""
    if not mask.any():
        return mask
    count, lab = labels(mask)
    keep = np.bincount(lab, minlength=count) >= min_share * mask.size
    keep[0] = False
    out: np.ndarray = keep[lab].reshape(mask.shape)
    return out


def labels(mask: np.ndarray) -> tuple[int, np.ndarray]:
    """8-connected components of ``mask``: their count (with the background, label 0) and the labels,
    flattened."""
    count, lab = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
    return int(count), lab.ravel()


_GRID: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}


def component_shape(
    lab: np.ndarray, count: int, shape: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per component (index 0 = background): area, length and width in pixels from second moments.

    A uniform bar of length L has variance L^2 / 12 along it (+1/12 for a pixel's own extent)."""
    grid = _GRID.get(shape)
    if grid is None:
        ys, xs = np.indices(shape, dtype=np.float64)
        grid = _GRID.setdefault(shape, (xs.ravel(), ys.ravel()))
    on = np.flatnonzero(lab)  # only the components' own pixels
    sub, xs, ys = lab[on], grid[0][on], grid[1][on]
    area = np.bincount(sub, minlength=count).astype(np.float64)
    safe = np.maximum(area, 1.0)
    mx = np.bincount(sub, xs, count) / safe
    my = np.bincount(sub, ys, count) / safe
    cxx = np.bincount(sub, xs * xs, count) / safe - mx * mx
    cyy = np.bincount(sub, ys * ys, count) / safe - my * my
    cxy = np.bincount(sub, xs * ys, count) / safe - mx * my
    half = (cxx + cyy) / 2
    root = np.sqrt(np.maximum(half**2 - (cxx * cyy - cxy**2), 0.0))
    length = np.sqrt(12.0 * (half + root) + 1.0)
    width = np.sqrt(12.0 * np.maximum(half - root, 0.0) + 1.0)
    return area, length, width


def touching(mask: np.ndarray, lab: np.ndarray, count: int, beside: np.ndarray, p: CueParams) -> np.ndarray:
    """Per component: does ``shadow_touch`` of its outline (inside the image) lie on ``beside``?"""
    # cv2.erode treats outside the image as set, so the image's border is no outline.
    outline = np.flatnonzero(mask & ~cv2.erode(mask.view(np.uint8), K3).view(bool))
    total = np.bincount(lab[outline], minlength=count)
    touch = np.bincount(lab[outline], beside.ravel()[outline], count)
    out: np.ndarray = (touch >= p.shadow_touch * total) & (touch > 0)
    return out


def in_focus(lab: np.ndarray, count: int, focus: np.ndarray | None) -> np.ndarray:
    """Per component: does at least half of it lie on the focus region (all do without one)?"""
    if focus is None:
        return np.ones(count, bool)
    out: np.ndarray = np.bincount(lab, focus.ravel(), count) >= 0.5 * np.bincount(lab, minlength=count)
    return out


def touching_focus(lab: np.ndarray, count: int, focus: np.ndarray | None) -> np.ndarray:
    """Per component: does it touch the focus region, widened by 2 px (all do without one)?"""
    if focus is None:
        return np.ones(count, bool)
    out: np.ndarray = np.bincount(lab, near(focus).ravel(), count) > 0
    return out


def drop_lines(mask: np.ndarray, p: CueParams) -> np.ndarray:
    """``mask`` without its thin straight components."""
    if not mask.any():
        return mask
    count, lab = labels(mask)
    _area, length, width = component_shape(lab, count, mask.shape)
    keep = ~is_line(length, width, p)
    keep[0] = False
    out: np.ndarray = keep[lab].reshape(mask.shape)
    return out


def is_line(length: np.ndarray, width: np.ndarray, p: CueParams) -> np.ndarray:
    """Per component: long, thin and straight enough to be a line (by its second moments)."""
    out: np.ndarray = (
        (length >= p.line_min_len_px) & (width <= p.line_max_width_px) & (length >= p.line_elongation * width)
    )
    return out


def background(img8: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-pixel colour (r, g, b planes, float32 0..1) of the surface under it: block medians, then a
    5 x 5 median over blocks, scaled back up (the whole image's median when it is small). Medians, not
    means, so a large object or its shadow does not tint the surface around it."""
    h, w = img8.shape[:2]
    side = min(h, w)
    if side < 16:
        med = np.median(img8.reshape(-1, 3), axis=0) / 255.0
        return tuple(np.full((h, w), v, np.float32) for v in med)  # type: ignore[return-value]
    block = max(2, side // 10)
    # Blocks of 4 px or more are sampled at every other pixel: the median of a quarter is as good.
    sub, bs = (img8[::2, ::2], block // 2) if block >= 4 else (img8, block)
    hb, wb = sub.shape[0] // bs, sub.shape[1] // bs
    cells = sub[: hb * bs, : wb * bs].reshape(hb, bs, wb, bs, 3).transpose(0, 2, 4, 1, 3)
    cells = cells.reshape(hb, wb, 3, bs * bs)
    mid = bs * bs // 2
    coarse = np.ascontiguousarray(np.partition(cells, mid, axis=3)[..., mid])
    coarse = cv2.medianBlur(coarse, 5)
    up = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_LINEAR)
    r, g, b = (plane.astype(np.float32) * np.float32(1.0 / 255.0) for plane in cv2.split(up))
    return r, g, b


def chroma_distance(
    a: tuple[np.ndarray, np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> np.ndarray:
    """Largest difference of chromaticity (r, g, b over their sum), damped toward grey where dark."""
    damp = np.float32(0.03)
    sa = np.float32(1.0) / (a[0] + a[1] + a[2] + 3 * damp)
    sb = np.float32(1.0) / (b[0] + b[1] + b[2] + 3 * damp)
    out: np.ndarray = np.abs((a[0] + damp) * sa - (b[0] + damp) * sb)
    for k in (1, 2):
        np.maximum(out, np.abs((a[k] + damp) * sa - (b[k] + damp) * sb), out=out)
    return out


def wide_shadow(
    rgb: tuple[np.ndarray, np.ndarray, np.ndarray],
    lum: np.ndarray,
    lbg: np.ndarray,
    dark: np.ndarray,
    p: CueParams,
) -> np.ndarray:
    """Pixels under ``wide_shadow_ratio`` of the image's lit surface (the brightest tenth of its
    background) with that surface's chromaticity."""
    lit = lbg >= np.percentile(lbg[::2, ::2], 90)
    # the lit surface's colour: a homogeneous tenth, so its mean
    colour = tuple(np.full((1, 1), plane[lit].mean(), np.float32) for plane in rgb)
    level = float(sum(float(v[0, 0]) for v in colour)) / 3.0
    out: np.ndarray = (lum < p.wide_shadow_ratio * level) & ~dark
    out &= chroma_distance(rgb, colour) < p.chroma_tol  # type: ignore[arg-type]
    return out


def site_region(
    img8: np.ndarray,
    bg: tuple[np.ndarray, np.ndarray, np.ndarray],
    lum: np.ndarray,
    c: float,
    barrier: np.ndarray,
    p: CueParams,
) -> np.ndarray:
    """The surface under the centre: connected pixels of its colour, not crossing ``barrier`` (objects
    and darker pixels, gaps closed: a parapet and its shadow fence a roof in), its holes (the objects
    standing on it) filled."""
    h, w = lum.shape
    planes = tuple(plane.astype(np.float32) * np.float32(1.0 / 255.0) for plane in cv2.split(img8))
    cy, cx, k = h // 2, w // 2, max(1, min(h, w) // 16)
    # The site's colour is the background's at the centre: an object standing right under the vehicle
    # (a person) must not be taken for the site itself.
    middle = tuple(np.full((1, 1), plane[cy, cx], np.float32) for plane in bg)
    lc = float(sum(float(v[0, 0]) for v in middle)) / 3.0
    similar = np.abs(lum - lc) <= max(p.site_tol_min, p.site_tol_k * c)
    similar &= chroma_distance(planes, middle) <= p.site_chroma  # type: ignore[arg-type]
    similar &= ~cv2.morphologyEx(barrier.view(np.uint8), cv2.MORPH_CLOSE, K3).view(bool)
    count, lab = cv2.connectedComponents(similar.view(np.uint8), connectivity=4)
    core = lab[cy - k : cy + k + 1, cx - k : cx + k + 1]
    core = core[core > 0]
    if core.size == 0:  # the centre is all object or barrier: judge the whole window
        return np.ones((h, w), bool)
    region = lab == np.bincount(core).argmax()
    # Holes: the objects standing on the site, small parts of its complement. An object the window's
    # border cuts is still one (it meets the border over about its width); a strip along the border
    # (the roof's edge, just in view) is not.
    count, out_lab, stats, _ = cv2.connectedComponentsWithStats((~region).view(np.uint8), connectivity=8)
    area = stats[:, cv2.CC_STAT_AREA].astype(np.float64)
    rim = np.concatenate([out_lab[0], out_lab[-1], out_lab[1:-1, 0], out_lab[1:-1, -1]])
    contact = np.bincount(rim, minlength=count)
    hole = (area <= p.max_blob_share * h * w) & (contact <= 2.0 * np.sqrt(area))
    hole[0] = True  # label 0: the region itself
    out: np.ndarray = hole[out_lab]
    return out


def water_regions(blue: np.ndarray, near_dark: np.ndarray, p: CueParams) -> tuple[np.ndarray, np.ndarray]:
    """Water (large blue regions casting no shadow) and raised blue panels (casting one), as masks."""
    empty = np.zeros(blue.shape, bool)
    if not blue.any():
        return empty, empty
    count, lab = labels(blue)
    area = np.bincount(lab, minlength=count)
    region = area >= p.region_min_share * blue.size
    region[0] = False
    if not region.any():
        return empty, empty
    raised = touching(blue, lab, count, near_dark, p)
    water = (region & ~raised)[lab].reshape(blue.shape)
    panels = (region & raised)[lab].reshape(blue.shape)
    return water, panels


def region_share(mask: np.ndarray, n: float, focus: np.ndarray | None, p: CueParams) -> float:
    """Share (of ``n`` pixels, on ``focus`` when there is one) in regions of ``mask`` of at least
    ``region_min_share`` of the image."""
    if not mask.any():
        return 0.0
    count, lab = labels(mask)
    region = np.bincount(lab, minlength=count) >= p.region_min_share * mask.size
    region[0] = False
    keep = region[lab]
    if focus is not None:
        keep &= focus.ravel()
    return min(1.0, float(np.count_nonzero(keep)) / n)


def edges(
    lum: np.ndarray, c: float, focus: np.ndarray | None, shadow: np.ndarray, p: CueParams
) -> tuple[float, float]:
    """Edge density at the working scale, and its coefficient of variation over 4 x 4 blocks. Edges on
    ``shadow`` (the rims of large cast shadows: a building's, a tower's) are no clutter and do not count."""
    h, w = lum.shape
    if min(h, w) < 8:
        return 0.0, 0.0
    sm = cv2.GaussianBlur(lum, (0, 0), 1.0)
    gx = cv2.Sobel(sm, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(sm, cv2.CV_32F, 0, 1, ksize=3)
    # Sobel's 3 x 3 kernel weighs a unit step per pixel 8 times over.
    on_edge = ((gx * gx + gy * gy) > np.float32((8.0 * p.edge_k * c) ** 2)) & ~shadow
    if focus is not None:
        on_edge &= focus
    area = h * w if focus is None else max(int(np.count_nonzero(focus)), 1)
    density = float(np.count_nonzero(on_edge)) / area
    if density == 0.0:
        return 0.0, 0.0
    blocks = cv2.resize(on_edge.view(np.uint8).astype(np.float32), (4, 4), interpolation=cv2.INTER_AREA)
    return density, float(blocks.std() / max(float(blocks.mean()), 1e-6))


def grain(lum: np.ndarray, lbg: np.ndarray, p: CueParams) -> tuple[float, bool]:
    """Relative amplitude of the fine texture, and whether it is spread evenly over 4 x 4 blocks."""
    h, w = lum.shape
    if min(h, w) < 8:
        return 0.0, False
    fine = np.abs(lum - cv2.GaussianBlur(lum, (0, 0), 1.0))
    level = max(float(np.median(lbg[::2, ::2])), 0.05)
    amplitude = 1.4826 * float(np.median(fine[::2, ::2])) / level
    blocks = cv2.resize(fine, (4, 4), interpolation=cv2.INTER_AREA)
    cv = float(blocks.std() / max(float(blocks.mean()), 1e-6))
    return amplitude, amplitude >= p.grain_min and cv < p.grain_cv
