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
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image as _PILImage

from ._validate import as_image

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

_WRITE_EXTENSIONS = {".png": 16, ".tif": 16, ".tiff": 16, ".jpg": 8, ".jpeg": 8}


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


def _to_storage(image: Any, bit_depth: int) -> NDArray[Any]:
    arr = as_image(image, "image")
    c = arr.shape[2]
    if c not in (1, 3, 4):
        raise ValueError(f"image: expected 1 (gray), 3 (RGB) or 4 (RGBA) channels to write, got {c}")
    scale, dtype = (255.0, np.uint8) if bit_depth == 8 else (65535.0, np.uint16)
    out: NDArray[Any] = np.rint(np.clip(arr, 0.0, 1.0) * scale).astype(dtype)
    if c == 3:
        out = out[:, :, ::-1]
    elif c == 4:
        out = out[:, :, [2, 1, 0, 3]]
    return np.ascontiguousarray(out[:, :, 0] if c == 1 else out)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _atomic_write(path: Path, data: bytes, overwrite: bool) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp makes the file private (0600); an output file gets the usual umask mode.
        os.chmod(tmp, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        if overwrite:
            os.replace(tmp, path)
        else:
            try:
                os.link(tmp, path)  # fails atomically if path exists
            except FileExistsError:
                raise FileExistsError(
                    f"out: {path} already exists (pass overwrite=True / --force to replace it)"
                ) from None
            except OSError:
                if path.exists():
                    raise FileExistsError(f"out: {path} already exists (pass overwrite=True / --force)") from None
                os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _check_target(path: Path, overwrite: bool) -> None:
    if not path.parent.is_dir():
        raise FileNotFoundError(f"out: folder {path.parent} does not exist")
    if path.exists() and not overwrite:
        raise FileExistsError(f"out: {path} already exists (pass overwrite=True / --force to replace it)")


def _encode(path: Path, image: Any, bit_depth: int | None) -> bytes:
    ext = path.suffix.lower()
    if ext not in _WRITE_EXTENSIONS:
        raise ValueError(f"out: unsupported extension {ext!r}; expected one of {sorted(_WRITE_EXTENSIONS)}")
    depth = bit_depth if bit_depth is not None else 8
    if depth not in (8, 16):
        raise ValueError(f"bit_depth: expected 8 or 16, got {depth}")
    if depth > _WRITE_EXTENSIONS[ext]:
        raise ValueError(f"bit_depth: {ext} files hold at most {_WRITE_EXTENSIONS[ext]} bits per channel, got {depth}")
    params = [cv2.IMWRITE_JPEG_QUALITY, 95] if ext in (".jpg", ".jpeg") else []
    ok, buf = cv2.imencode(ext, _to_storage(image, depth), params)
    if not ok:
        raise RuntimeError(f"out: OpenCV could not encode {path.name}")
    return buf.tobytes()


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
    data = _encode(p, image, bit_depth)
    _check_target(p, overwrite)
    _atomic_write(p, data, overwrite)


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The JSON sidecar of an output file: ``out.png`` → ``out.png.json``."""
    p = Path(path)
    return p.with_name(p.name + ".json")


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

    Both targets are checked before either is written, so a refused overwrite leaves nothing
    behind. Returns the sidecar's path.
    """
    from . import __version__

    p = Path(path)
    side = sidecar_path(p)
    data = _encode(p, image, bit_depth)
    _check_target(p, overwrite)
    _check_target(side, overwrite)
    meta = {
        "phloem_version": __version__,
        "command": command,
        "seed": seed,
        "parameters": {k: (str(v) if isinstance(v, os.PathLike) else v) for k, v in parameters.items()},
        "output": p.name,
    }
    _atomic_write(p, data, overwrite)
    _atomic_write(side, (json.dumps(meta, indent=2, sort_keys=True) + "\n").encode(), overwrite)
    return side
