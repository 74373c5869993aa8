"""Reading and writing images and result sidecars.

Images are read as float32 arrays in [0, 1] — ``(H, W)`` gray or ``(H, W, C)`` RGB / RGBA in
that channel order — from 8- and 16-bit PNG, JPEG and TIFF files. The image size is read from
the file header and checked against a pixel limit *before* any pixel is decoded, so a
decompression bomb costs nothing. Writes are atomic (a temporary file in the same folder, then
a rename) and never replace an existing file unless asked.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image as _PILImage

from ._files import Transaction, encode

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "ImageReadError",
    "read_image",
    "sidecar_path",
    "write_image",
    "write_result",
]

#: Largest image (width × height) :func:`read_image` decodes unless told otherwise: 2**28
#: pixels, about 16k × 16k, or 1 GiB as float32 RGB.
DEFAULT_MAX_PIXELS = 2**28


class ImageReadError(ValueError):
    """A file could not be read as an image (missing, corrupt, truncated or too large)."""


def _header(path: Path, max_pixels: int) -> tuple[str, int, int]:
    try:
        with _PILImage.open(path) as im:
            fmt, (w, h) = im.format or "?", im.size
            if fmt == "PNG":
                im.verify()  # chunk CRCs: catches corruption and truncation without decoding
    except FileNotFoundError:
        raise ImageReadError(f"path: no such file: {path}") from None
    except IsADirectoryError:
        raise ImageReadError(f"path: {path} is a folder, not an image file") from None
    except _PILImage.DecompressionBombError:
        raise ImageReadError(f"path: {path} exceeds the pixel limit of {max_pixels} pixels") from None
    except (OSError, SyntaxError, ValueError) as e:
        raise ImageReadError(f"path: {path} is not a readable PNG, JPEG or TIFF image ({e})") from None
    if fmt not in ("PNG", "JPEG", "TIFF", "MPO"):
        raise ImageReadError(f"path: {path} is a {fmt} file; expected PNG, JPEG or TIFF")
    if w * h > max_pixels:
        raise ImageReadError(
            f"path: {path} is {w}×{h} = {w * h} pixels, over the limit of {max_pixels}"
            " (pass a larger max_pixels / --max-pixels if you trust this file)"
        )
    return fmt, w, h


def read_image(path: str | os.PathLike[str], *, max_pixels: int = DEFAULT_MAX_PIXELS) -> NDArray[np.float32]:
    """Read an image file as a float32 array in [0, 1].

    Parameters
    ----------
    path : str or path-like
        A PNG, JPEG or TIFF file with 8 or 16 bits per channel, gray, RGB or RGBA.
    max_pixels : int, optional
        Refuse images with more pixels than this (default :data:`DEFAULT_MAX_PIXELS`). The
        size comes from the header, so the check happens before decoding.

    Returns
    -------
    image : (M, N) or (M, N, C) ndarray of float32
        Gray images are 2-D; colour images are RGB or RGBA, in that order.

    Raises
    ------
    ImageReadError
        If the file is missing, not an image, corrupt, truncated or over ``max_pixels``.

    Examples
    --------
    >>> import phloem, tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "bark.png")
    >>> phloem.io.write_image(path, phloem.data.bark())
    >>> phloem.io.read_image(path).shape
    (256, 256, 4)
    """
    p = Path(path)
    if int(max_pixels) < 1:
        raise ValueError(f"max_pixels: expected a positive pixel count, got {max_pixels}")
    fmt, w, h = _header(p, int(max_pixels))
    raw = np.fromfile(p, dtype=np.uint8)
    if fmt in ("JPEG", "MPO") and b"\xff\xd9" not in raw[-64:].tobytes():
        raise ImageReadError(f"path: {p} is a truncated JPEG (no end-of-image marker)")
    img = cv2.imdecode(raw, cv2.IMREAD_UNCHANGED)
    if img is None or img.shape[0] != h or img.shape[1] != w:
        raise ImageReadError(f"path: {p} could not be decoded as a {fmt} image")
    if img.dtype == np.uint8:
        out = img.astype(np.float32) / 255.0
    elif img.dtype == np.uint16:
        out = img.astype(np.float32) / 65535.0
    elif img.dtype == np.float32:
        out = img.astype(np.float32)
    else:
        raise ImageReadError(f"path: {p} has {img.dtype} samples; expected 8- or 16-bit integers")
    if out.ndim == 3:
        if out.shape[2] == 3:
            out = out[:, :, ::-1]
        elif out.shape[2] == 4:
            out = out[:, :, [2, 1, 0, 3]]
    return np.ascontiguousarray(out, dtype=np.float32)


def write_image(
    path: str | os.PathLike[str], image: Any, *, overwrite: bool = False, bit_depth: int | None = None
) -> None:
    """Write an image atomically; values are clipped to [0, 1] and quantised.

    Parameters
    ----------
    path : str or path-like
        Destination; the extension picks the format (``.png``, ``.jpg``/``.jpeg``,
        ``.tif``/``.tiff``).
    image : (M, N[, C]) array_like
        Gray (C = 1), RGB (3) or RGBA (4). Integer dtypes are scaled by their maximum.
    overwrite : bool, optional
        Replace an existing file. By default an existing file raises ``FileExistsError`` and
        nothing is written.
    bit_depth : {8, 16}, optional
        Bits per channel (default 8; 16 for PNG and TIFF only).
    """
    p = Path(path)
    data = encode(p, image, bit_depth)
    with Transaction(overwrite) as tx:
        tx.stage(p, data)
        tx.commit()


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The JSON sidecar of an output file: ``out.png`` → ``out.png.json``."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def _sidecar(path: Path, command: str, parameters: Mapping[str, Any], seed: int | None, default: Any = None) -> bytes:
    """The bytes of ``path``'s sidecar: parameters, seed and phloem version."""
    from . import __version__

    meta = {
        "phloem_version": __version__,
        "command": command,
        "seed": seed,
        "parameters": {k: (str(v) if isinstance(v, os.PathLike) else v) for k, v in parameters.items()},
        "output": path.name,
    }
    return (json.dumps(meta, indent=2, sort_keys=True, default=default) + "\n").encode()


def write_result(
    path: str | os.PathLike[str],
    image: Any,
    *,
    command: str,
    parameters: Mapping[str, Any],
    seed: int | None,
    overwrite: bool = False,
    bit_depth: int | None = None,
) -> Path:
    """Write an output image and its sidecar (parameters, seed, phloem version).

    Both targets are checked before either is written, and both take their names together, so
    a refused overwrite or a failed write (a full disk) leaves neither behind. Returns the
    sidecar's path.
    """
    p = Path(path)
    side = sidecar_path(p)
    data = encode(p, image, bit_depth)
    with Transaction(overwrite) as tx:
        tx.reserve(p)
        tx.reserve(side)
        tx.stage(p, data)
        tx.stage(side, _sidecar(p, command, parameters, seed))
        tx.commit()
    return side
