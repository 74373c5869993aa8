"""A quick look at a bark texture: wrapped round a lit trunk."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .._validate import as_image

__all__ = ["cylinder_preview"]


def cylinder_preview(
    texture: Any,
    *,
    height: Any = None,
    bump: float = 2.0,
    light: tuple[float, float, float] = (-0.6, 0.4, 1.0),
    ambient: float = 0.3,
) -> NDArray[np.float32]:
    """The texture wrapped once around a vertical trunk, seen from the front (orthographic).

    The texture's width is the trunk's circumference, so the visible half shows half of it, with
    the columns squeezed towards the silhouette as on a real trunk. Lambert shading from
    ``light``; with a ``height`` map, its gradient (scaled by ``bump``) tilts the normals.

    Parameters
    ----------
    texture : array_like, shape (H, W, C) or (H, W)
    height : array_like, shape (H, W), optional
    bump : float, optional
        Strength of the height map's relief (default 2).
    light : (float, float, float), optional
        Direction towards the light (x right, y up, z towards the viewer).
    ambient : float, optional
        Light reaching every visible point (default 0.3).

    Returns
    -------
    numpy.ndarray of float32, shape (H, round(W / π) + 2, C)
        Black outside the trunk.

    Examples
    --------
    >>> import phloem
    >>> phloem.bark.cylinder_preview(phloem.data.bark()[..., :3]).shape
    (256, 83, 3)
    """
    tex = as_image(texture, "texture")
    h, w, _ = tex.shape

    radius = w / (2 * math.pi)
    out_w = round(2 * radius) + 2
    xs = (np.arange(out_w, dtype=np.float64) + 0.5 - out_w / 2) / radius
    inside = np.abs(xs) < 1
    theta = np.arcsin(np.clip(xs, -1, 1))
    u = (theta / (2 * math.pi) + 0.25) * w  # the front half shows columns w/4 … 3w/4 around the centre w/2
    mapx = np.ascontiguousarray(np.broadcast_to((u - 0.5).astype(np.float32), (h, out_w)))
    mapy = np.ascontiguousarray(np.broadcast_to(np.arange(h, dtype=np.float32)[:, None], (h, out_w)))
    img = cv2.remap(tex, mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    if img.ndim == 2:
        img = img[:, :, None]
    nx = np.broadcast_to(np.sin(theta), (h, out_w)).copy()
    ny = np.zeros((h, out_w))
    nz = np.broadcast_to(np.cos(theta), (h, out_w)).copy()
    if height is not None:
        hm = as_image(height, "height")
        if hm.shape[:2] != (h, w):
            raise ValueError(f"height: expected shape {(h, w)} to match texture, got {hm.shape[:2]}")
        hv = cv2.remap(hm[..., 0], mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        du = np.gradient(hv, axis=1) * bump
        dv = np.gradient(hv, axis=0) * bump
        # tangent frame: around the trunk (cos θ, 0, -sin θ) and up (0, 1, 0); image rows grow downwards
        nx, ny, nz = nx - du * np.cos(theta), ny + dv, nz + du * np.sin(theta)
    norm = np.sqrt(nx**2 + ny**2 + nz**2)
    lv = np.asarray(light, np.float64)
    lv = lv / np.linalg.norm(lv)
    shade = ambient + (1 - ambient) * np.clip((nx * lv[0] + ny * lv[1] + nz * lv[2]) / norm, 0, None)
    res = img * shade[:, :, None].astype(np.float32)
    res[:, ~inside] = 0
    return np.ascontiguousarray(res, dtype=np.float32)
