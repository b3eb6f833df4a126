"""How the sensors see overhead wires (:class:`~simbridge.world.world.Wire`), which are not in the grid.

The camera draws each wire's straight pieces over the rendered image (:func:`draw_wires`): a line as
wide as the conductor's projected diameter, at least ``MIN_WIDTH_PX``, darkened in proportion to how
much of each pixel the conductor covers, so a 2 cm conductor 30 m below a 960 px, 90-degree camera
(0.3 px) is a faint dark line and 5 m below (2 px) a plain one. A pixel whose rendered surface is
nearer the camera than the wire (a building between them) is left alone: the frame's depth map is the
occlusion test. The LiDAR returns at a wire only now and then (:func:`wire_returns`): a beam passing
within ``BEAM_RADIUS_M`` of a conductor, nearer than what it hits in the grid, comes back from the wire
with probability ``WIRE_RETURN_P``, as a spinning LiDAR's few points on a thin cable. Both are separate
vectorised passes after the ray casting, and cost nothing for a world without wires.
"""

from __future__ import annotations

import numpy as np

from simbridge.world.world import Wire

MIN_WIDTH_PX = 0.6
WIRE_RGB = np.array([32.0, 32.0, 36.0])  # a weathered conductor
NEAR_M = 0.3  # the camera ignores what is nearer than this
PIECE_PX = 4.0  # projected pieces at most this long, each drawn in its own small window
MAX_HALF_WINDOW_PX = 12
OCCLUSION_M = 0.3  # a surface this much nearer than the wire hides it
BEAM_RADIUS_M = 0.03  # half the beam's footprint at the ranges that matter
WIRE_RETURN_P = 0.2
SAMPLE_M = 0.2  # spacing of the points that find the LiDAR rays passing near a conductor


def segments(wires: tuple[Wire, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The wires' straight pieces: starts and ends (S, 3) north, east, up metres, and diameters (S,)."""
    starts, ends, diam = [], [], []
    for w in wires:
        p = np.asarray(w.points_neh, np.float64).reshape(-1, 3)
        if len(p) < 2:
            continue
        starts.append(p[:-1])
        ends.append(p[1:])
        diam.append(np.full(len(p) - 1, w.diameter_m))
    if not starts:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(starts), np.concatenate(ends), np.concatenate(diam)


def _clip_2d(p0: np.ndarray, p1: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Liang-Barsky: the parameter range [t0, t1] of each 2-D segment inside the box (t0 > t1: none)."""
    d = p1 - p0
    t0, t1 = np.zeros(len(p0)), np.ones(len(p0))
    for k in (0, 1):
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = (lo[k] - p0[:, k]) / d[:, k]
            tb = (hi[k] - p0[:, k]) / d[:, k]
        flat = d[:, k] == 0
        outside = flat & ((p0[:, k] < lo[k]) | (p0[:, k] > hi[k]))
        t0 = np.where(flat, t0, np.maximum(t0, np.minimum(ta, tb)))
        t1 = np.where(flat, t1, np.minimum(t1, np.maximum(ta, tb)))
        t1 = np.where(outside, -1.0, t1)
    return t0, t1


def draw_wires(
    rgb: np.ndarray,
    depth_m: np.ndarray,
    wires: tuple[Wire, ...],
    r_neu_cam: np.ndarray,
    origin_neu: np.ndarray,
    focal_px: float,
) -> np.ndarray:
    """The image with the wires drawn over it.

    Args:
        rgb: (H, W, 3) uint8 rendered image.
        depth_m: (H, W) z-depth of what each pixel sees (NaN: nothing), the occlusion test.
        wires: the world's wires.
        r_neu_cam: (3, 3) rotation whose columns are the camera's x (right), y (down), z (optical
            axis) in (north, east, up).
        origin_neu: (3,) the camera's position, (north, east, up) metres.
        focal_px: the focal length in pixels (principal point at the image centre).

    Returns:
        A new (H, W, 3) uint8 image; ``rgb`` itself when no wire is in view.
    """
    a, b, diam = segments(wires)
    h, w = depth_m.shape
    pa, pb = (a - origin_neu) @ r_neu_cam, (b - origin_neu) @ r_neu_cam  # camera frame (x, y, z)
    za, zb = pa[:, 2], pb[:, 2]
    front = (za > NEAR_M) | (zb > NEAR_M)
    pa, pb, za, zb, diam = pa[front], pb[front], za[front], zb[front], diam[front]
    # clip to the near plane in 3-D, where straight stays straight
    ta = np.clip((NEAR_M - za) / np.where(zb != za, zb - za, 1.0), 0.0, 1.0)
    pa = np.where((za < NEAR_M)[:, None], pa + ta[:, None] * (pb - pa), pa)
    tb = np.clip((NEAR_M - zb) / np.where(za != zb, za - zb, 1.0), 0.0, 1.0)
    pb = np.where((zb < NEAR_M)[:, None], pb + tb[:, None] * (pa - pb), pb)
    centre = np.array([w / 2, h / 2])
    qa = focal_px * pa[:, :2] / pa[:, 2:3] + centre  # pixel coordinates (pixel j covers [j, j + 1))
    qb = focal_px * pb[:, :2] / pb[:, 2:3] + centre
    iza, izb = 1.0 / pa[:, 2], 1.0 / pb[:, 2]  # inverse depth: linear on the image
    margin = MAX_HALF_WINDOW_PX
    t0, t1 = _clip_2d(qa, qb, np.array([-margin, -margin]), np.array([w + margin, h + margin]))
    seen = t1 > t0
    if not seen.any():
        return rgb
    qa, qb, iza, izb, diam, t0, t1 = qa[seen], qb[seen], iza[seen], izb[seen], diam[seen], t0[seen], t1[seen]
    # cut each visible stretch into pieces at most PIECE_PX long
    length = np.hypot(*(qb - qa).T) * (t1 - t0)
    n_pieces = np.maximum(np.ceil(length / PIECE_PX).astype(np.int64), 1)
    seg = np.repeat(np.arange(len(qa)), n_pieces)
    k = np.arange(len(seg)) - np.repeat(np.cumsum(n_pieces) - n_pieces, n_pieces)
    s0 = t0[seg] + (t1 - t0)[seg] * k / n_pieces[seg]
    s1 = t0[seg] + (t1 - t0)[seg] * (k + 1) / n_pieces[seg]
    e0 = qa[seg] + s0[:, None] * (qb - qa)[seg]
    e1 = qa[seg] + s1[:, None] * (qb - qa)[seg]
    iz0 = iza[seg] + s0 * (izb - iza)[seg]
    iz1 = iza[seg] + s1 * (izb - iza)[seg]
    d_px = diam[seg] * focal_px * (iz0 + iz1) / 2  # the conductor's projected diameter
    half_w = np.maximum(d_px, MIN_WIDTH_PX) / 2
    fade = np.minimum(d_px / (2 * half_w), 1.0)  # thinner than the drawn line: lighter
    reach = int(min(np.ceil(PIECE_PX / 2 + half_w.max() + 1.0), MAX_HALF_WINDOW_PX))
    mid = (e0 + e1) / 2
    off = np.arange(-reach, reach + 1)
    px = np.floor(mid[:, 0])[:, None, None] + off[None, None, :]  # (P, 1, R) columns
    py = np.floor(mid[:, 1])[:, None, None] + off[None, :, None]  # (P, R, 1) rows
    cx, cy = px + 0.5, py + 0.5
    dx, dy = (e1 - e0)[:, 0, None, None], (e1 - e0)[:, 1, None, None]
    len2 = np.maximum(dx * dx + dy * dy, 1e-12)
    u = np.clip(((cx - e0[:, 0, None, None]) * dx + (cy - e0[:, 1, None, None]) * dy) / len2, 0.0, 1.0)
    dist = np.hypot(cx - e0[:, 0, None, None] - u * dx, cy - e0[:, 1, None, None] - u * dy)
    cover = np.clip(half_w[:, None, None] + 0.5 - dist, 0.0, 1.0) * fade[:, None, None]
    z = 1.0 / (iz0[:, None, None] + u * (iz1 - iz0)[:, None, None])
    px, py, cover, z = np.broadcast_arrays(px, py, cover, z)
    inside = (cover > 0) & (px >= 0) & (px < w) & (py >= 0) & (py < h)
    col, row = px[inside].astype(np.intp), py[inside].astype(np.intp)
    behind = depth_m[row, col] < z[inside] - OCCLUSION_M  # NaN (sky): never
    alpha = np.zeros(h * w)
    np.maximum.at(alpha, (row * w + col)[~behind], cover[inside][~behind])
    if not alpha.any():
        return rgb
    a3 = alpha.reshape(h, w, 1)
    out = rgb.astype(np.float64) * (1.0 - a3) + WIRE_RGB * a3
    return np.asarray(np.clip(np.rint(out), 0, 255), np.uint8)


def wire_returns(
    wires: tuple[Wire, ...],
    dirs_neu: np.ndarray,
    origin_neu: np.ndarray,
    rings: tuple[int, int, float],
    r_body_neu: np.ndarray,
    range_m: float,
    grid_t: np.ndarray,
    grid_hit: np.ndarray,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """The LiDAR rays that come back from a wire this sweep, and their ranges.

    Args:
        wires: the world's wires.
        dirs_neu: (N, 3) unit rays in (north, east, up), ring by ring (``LidarModel.rays_body``).
        origin_neu: (3,) the sensor's position.
        rings: (channels, points_per_ring, min_elevation_deg) of the model that cast the rays.
        r_body_neu: (3, 3) rotation body FRD -> (north, east, up).
        range_m: the LiDAR's range.
        grid_t: (N,) range to what each ray hits in the grid; ``grid_hit`` (N,) whether it hit at all.
        rng: draws which of the rays passing near a conductor return from it (nothing is drawn when
            no ray passes near one).

    Returns:
        (indices into the rays, ranges in metres) of the wire returns.
    """
    none = (np.zeros(0, np.intp), np.zeros(0))
    a, b, diam = segments(wires)
    if not len(a):
        return none
    v = b - a
    c = np.maximum((v * v).sum(axis=1), 1e-12)
    s = np.clip(((origin_neu - a) * v).sum(axis=1) / c, 0.0, 1.0)
    gap = np.linalg.norm(a + s[:, None] * v - origin_neu, axis=1)
    keep = gap <= range_m
    if not keep.any():
        return none
    idx = np.flatnonzero(keep)
    lengths = np.sqrt(c[idx])
    n_s = np.maximum(np.ceil(lengths / SAMPLE_M).astype(np.int64), 1) + 1
    seg = np.repeat(idx, n_s)
    k = np.arange(len(seg)) - np.repeat(np.cumsum(n_s) - n_s, n_s)
    pts = a[seg] + (k / np.repeat(n_s - 1, n_s))[:, None] * v[seg]
    body = (pts - origin_neu) @ r_body_neu  # rows: body FRD
    r = np.linalg.norm(body, axis=1)
    ok = (r > 0.05) & (r <= range_m)
    body, seg, r = body[ok], seg[ok], r[ok]
    channels, per_ring, min_el = rings
    el = np.degrees(np.arcsin(np.clip(body[:, 2] / r, -1.0, 1.0)))
    az = np.mod(np.arctan2(body[:, 1], body[:, 0]), 2 * np.pi)
    ring_f = (el - min_el) / max(90.0 - min_el, 1e-9) * max(channels - 1, 1)
    col_f = az / (2 * np.pi) * per_ring
    cand_ray, cand_seg = [], []
    for dr in (0, 1):
        for dc in (0, 1):
            ring = np.floor(ring_f).astype(np.int64) + dr
            col = np.mod(np.floor(col_f).astype(np.int64) + dc, per_ring)
            valid = (ring >= 0) & (ring < channels)
            cand_ray.append((ring * per_ring + col)[valid])
            cand_seg.append(seg[valid])
    pairs = np.unique(np.stack([np.concatenate(cand_ray), np.concatenate(cand_seg)], axis=1), axis=0)
    if not len(pairs):
        return none
    ray, sg = pairs[:, 0], pairs[:, 1]
    d = dirs_neu[ray]
    w0 = origin_neu - a[sg]
    vv = v[sg]
    bb = (d * vv).sum(axis=1)
    dd = (d * w0).sum(axis=1)
    ee = (vv * w0).sum(axis=1)
    cc = c[sg]
    ss = np.clip((ee - bb * dd) / np.maximum(cc - bb * bb, 1e-12), 0.0, 1.0)
    t = ss * bb - dd
    miss = np.linalg.norm(w0 + t[:, None] * d - ss[:, None] * vv, axis=1)
    hit = (t > 0.05) & (t <= range_m) & (miss <= diam[sg] / 2 + BEAM_RADIUS_M)
    hit &= ~grid_hit[ray] | (t < grid_t[ray])
    if not hit.any():
        return none
    ray, t = ray[hit], t[hit]
    order = np.lexsort((t, ray))  # the nearest conductor on each ray
    ray, t = ray[order], t[order]
    first = np.concatenate([[True], ray[1:] != ray[:-1]])
    ray, t = ray[first], t[first]
    back = rng.random(len(ray)) < WIRE_RETURN_P
    return ray[back].astype(np.intp), t[back]
