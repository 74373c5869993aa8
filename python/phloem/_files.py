"""Writing output files: encoding, atomic creation without silent overwrite, target checks.

Shared by ``phloem.io`` and the command line, which must write several files of one run.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ._validate import as_image

WRITE_EXTENSIONS = {".png": 16, ".tif": 16, ".tiff": 16, ".jpg": 8, ".jpeg": 8}


def to_storage(image: Any, bit_depth: int) -> NDArray[Any]:
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


def umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: Path, data: bytes, overwrite: bool) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp makes the file private (0600); an output file gets the usual umask mode.
        os.chmod(tmp, 0o666 & ~umask())
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


def check_target(path: Path, overwrite: bool) -> None:
    if not path.parent.is_dir():
        raise FileNotFoundError(f"out: folder {path.parent} does not exist")
    if path.exists() and not overwrite:
        raise FileExistsError(f"out: {path} already exists (pass overwrite=True / --force to replace it)")


def encode(path: Path, image: Any, bit_depth: int | None) -> bytes:
    ext = path.suffix.lower()
    if ext not in WRITE_EXTENSIONS:
        raise ValueError(f"out: unsupported extension {ext!r}; expected one of {sorted(WRITE_EXTENSIONS)}")
    depth = bit_depth if bit_depth is not None else 8
    if depth not in (8, 16):
        raise ValueError(f"bit_depth: expected 8 or 16, got {depth}")
    if depth > WRITE_EXTENSIONS[ext]:
        raise ValueError(f"bit_depth: {ext} files hold at most {WRITE_EXTENSIONS[ext]} bits per channel, got {depth}")
    params = [cv2.IMWRITE_JPEG_QUALITY, 95] if ext in (".jpg", ".jpeg") else []
    ok, buf = cv2.imencode(ext, to_storage(image, depth), params)
    if not ok:
        raise RuntimeError(f"out: OpenCV could not encode {path.name}")
    return buf.tobytes()
