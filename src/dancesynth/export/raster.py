"""Pixels for the video renderer: Y'CbCr conversion, packed RGB, box-filtered supersampling and
anti-aliased lines, apart from the scene (``render``) that uses them."""

from __future__ import annotations

import numpy as np
from PIL import Image


# BT.601 limited-range Y'CbCr from RGB, the matrix H.264's default tags mean
_BT601 = np.array([[65.481, 128.553, 24.966], [-37.797, -74.203, 112.0], [112.0, -93.786, -18.214]])


def to_ycbcr(rgb) -> np.ndarray:
    """BT.601 limited-range Y'CbCr (..., 3) of 8-bit sRGB colours (..., 3), as ffmpeg converts RGB for H.264."""
    rgb = np.asarray(rgb, dtype=np.float64)
    return np.array([16.0, 128.0, 128.0]) + rgb @ (_BT601.T / 255.0)


def luma(rgb) -> np.ndarray:
    return to_ycbcr(rgb)[..., 0]


def pack(c) -> np.ndarray:
    """8-bit colours (..., 3) (rounded, clipped) packed in uint32, the first channel in the low byte (PIL's RGBX)."""
    c = np.clip(np.rint(c), 0, 255).astype(np.uint32)
    return c[..., 0] | c[..., 1] << 8 | c[..., 2] << 16


def unpack(packed: np.ndarray) -> np.ndarray:
    return np.stack([packed & 255, packed >> 8 & 255, packed >> 16 & 255], axis=-1).astype(np.float64)


def packed_image(packed: np.ndarray) -> Image.Image:
    """An RGBX image over packed colours (H, W) uint32 (no copy; drawing on it copies)."""
    return Image.frombuffer("RGBX", (packed.shape[1], packed.shape[0]), packed, "raw", "RGBX", 0, 1)


def box_reduce(img: Image.Image, factor: int) -> Image.Image:
    """Box-filtered down by ``factor`` (the drawing scale to the output's)."""
    return img.reduce(factor) if factor > 1 else img.copy()


_WIDER = {np.dtype(np.uint8): (np.uint16, 0x0101), np.dtype(np.uint32): (np.uint64, 0x100000001)}


def upsample(a: np.ndarray, factor: int) -> np.ndarray:
    """Each pixel of ``a`` (H, W) as a factor x factor block."""
    if factor == 1:
        return a.copy()
    if factor != 2 or a.dtype not in _WIDER:
        return a.repeat(factor, axis=0).repeat(factor, axis=1)
    # Twice as wide: each pixel twice in a number of twice its size (4x faster than np.repeat), then each row twice.
    wide, twice = _WIDER[a.dtype]
    row = (a.astype(wide) * wide(twice)).view(a.dtype).reshape(a.shape[0], 2 * a.shape[1])
    out = np.empty((2 * a.shape[0], 2 * a.shape[1]), a.dtype)
    out[0::2] = row
    out[1::2] = row
    return out


def image_planes(img: Image.Image) -> list[np.ndarray]:
    """The Y, Cb and Cr planes (uint8 arrays; Cb and Cr box-filtered to half size) of a Y'CbCr picture held
    in an RGBX image of even size."""
    half = img.reduce(2)
    return [np.asarray(img.getchannel(0)), np.asarray(half.getchannel(1)), np.asarray(half.getchannel(2))]


def smooth_lines(img: np.ndarray, p0: np.ndarray, p1: np.ndarray, depth: np.ndarray, base: float) -> None:
    """Anti-aliased lines, one pixel wide, from ``p0`` to ``p1`` (N, 2) pixels, into the luma image ``img``:
    each darkens the pixels it covers from ``base`` by up to ``depth`` (N,), in proportion to the part of
    each pixel it covers (a box filter); where lines cross, the darker wins."""
    h, w = img.shape
    steep = np.abs(p1[:, 1] - p0[:, 1]) > np.abs(p1[:, 0] - p0[:, 0])
    for group, (ia, ib), strides, extents in (((~steep), (0, 1), (1, w), (w, h)), (steep, (1, 0), (w, 1), (h, w))):
        _lines_along(img.reshape(-1), p0[group, ia], p1[group, ia], p0[group, ib], p1[group, ib], depth[group],
                     base, strides, extents)


def _lines_along(flat: np.ndarray, a0, a1, b0, b1, depth, base: float, strides, extents) -> None:
    """``smooth_lines`` of lines from (a0, b0) to (a1, b1) that run along a (x, or y for steep lines), with
    |slope| <= 1: one sample per pixel along a; across (b), the pixels the line's cross-section covers (a line
    1 pixel wide spans sqrt(1 + slope^2) pixels, so at most 3). ``strides``: a's and b's in ``flat``."""
    flip = a1 < a0
    a0, a1, b0, b1 = np.where(flip, a1, a0), np.where(flip, a0, a1), np.where(flip, b1, b0), np.where(flip, b0, b1)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(a1 - a0 > 1e-9, (b1 - b0) / (a1 - a0), 0.0)
    # Only where the line is on the picture: a within it, and b within it (give or take 2 pixels).
    with np.errstate(divide="ignore", invalid="ignore"):
        enter, leave = (a0 + (edge - b0) / slope for edge in (-2.0, extents[1] + 2.0))
    inside = (b0 >= -2) & (b0 <= extents[1] + 2)
    start = np.where(slope > 0, enter, np.where(slope < 0, leave, np.where(inside, a0, np.inf)))
    stop = np.where(slope > 0, leave, np.where(slope < 0, enter, np.where(inside, a1, -np.inf)))
    first = np.clip(np.ceil(np.maximum(a0, start) - 0.5), 0, extents[0])
    n = np.maximum(np.clip(np.ceil(np.minimum(a1, stop) - 0.5), 0, extents[0]) - first, 0).astype(np.int64)
    total = int(n.sum())
    if total == 0:
        return
    # One record per line, spread over its samples by a single np.repeat.
    record = np.stack([np.cumsum(n) - n, first, b0 + (first + 0.5 - a0) * slope, slope,
                       0.5 * np.sqrt(1.0 + slope * slope), depth], axis=1)
    r = np.repeat(record.astype(np.float32), n, axis=0).T.copy()   # (6, samples)
    k = np.arange(total, dtype=np.float32) - r[0]
    b = r[2] + k * r[3]
    lo, hi = b - r[4], b + r[4]
    along = (r[1] + k) * strides[0]                                   # exact in float32 up to 4K pictures
    pixel = np.floor(lo)
    at = np.empty((3, total), np.int64)
    value = np.empty((3, total), np.uint8)
    for j in range(3):  # the pixels across, each as whole rows of 1-D work (broadcasting (3, n) is slow)
        cover = np.minimum(hi, pixel + 1)
        cover -= np.maximum(lo, pixel)
        np.clip(cover, 0, 1, out=cover)
        darker = np.rint(base - cover * r[5])
        darker[(pixel < 0) | (pixel >= extents[1])] = 255          # off the picture: leaves it as it is
        value[j] = darker
        at[j] = along + np.clip(pixel, 0, extents[1] - 1) * strides[1]
        pixel += 1
    np.minimum.at(flat, at.ravel(), value.ravel())


def disc(d, centre, r: float, fill) -> None:
    if r < 0.75:
        return
    u, v = centre
    d.ellipse((u - r, v - r, u + r, v + r), fill=fill)
