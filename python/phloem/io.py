"""Reading and writing images and result sidecars.

Images are read as float32 arrays in [0, 1] — ``(H, W)`` gray or ``(H, W, C)`` RGB / RGBA in
that channel order — from 8- and 16-bit PNG, JPEG, TIFF and WebP files and from float TIFFs
(see :func:`read_image` for how float values are mapped). The image size is read from the file
header and checked against one pixel limit, ours, *before* any pixel is decoded, so a
decompression bomb costs nothing. EXIF orientation is applied, so photos read upright. Writes
are atomic (a temporary file in the same folder, then a rename) and never replace an existing
file unless asked.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import re
import struct
import threading
import warnings
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image as _PILImage
from PIL import JpegImagePlugin, PngImagePlugin, WebPImagePlugin

from ._files import Transaction, encode

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "IMAGE_SUFFIXES",
    "SIDECAR_VERSION",
    "ImageReadError",
    "RescaledImageWarning",
    "file_digest",
    "find_sidecar",
    "image_size",
    "read_image",
    "sidecar_path",
    "stored_bit_depth",
    "write_image",
    "write_result",
]

#: Largest image (width × height) :func:`read_image` decodes unless told otherwise: 2**28
#: pixels, about 16k × 16k, or 1 GiB as float32 RGB.
DEFAULT_MAX_PIXELS = 2**28

#: File name endings of the formats :func:`read_image` reads (it goes by the content, not the
#: name; folder readers such as :meth:`phloem.trees.Library.load` collect these).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".webp")

# OpenCV refuses to decode more pixels than this (its CV_IO_MAX_IMAGE_PIXELS default).
_CV2_MAX_PIXELS = 2**30


class ImageReadError(ValueError):
    """A file could not be read as an image (missing, corrupt, truncated or too large)."""


class RescaledImageWarning(UserWarning):
    """A float image had values outside [0, 1] and was rescaled from its min..max to [0, 1]."""


def _format(prefix: bytes) -> str | None:
    """The format of a file from its first bytes, for the formats we read; None for others."""
    if prefix.startswith(b"\x89PNG\r\n\x1a\n"):
        return "PNG"
    if prefix.startswith(b"\xff\xd8\xff"):
        return "JPEG"
    if prefix[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):  # classic and BigTIFF
        return "TIFF"
    if prefix[:4] == b"RIFF" and prefix[8:12] == b"WEBP":
        return "WEBP"
    return None


def _pillow_header(fp: IO[bytes], fmt: str) -> tuple[int, int, int]:
    """Width, height and EXIF orientation from Pillow's format plugin.

    The plugin classes are used directly, not ``Image.open``: that applies Pillow's own
    decompression-bomb ceiling (a warning above 89 Mpx, an error above 179 Mpx) that is not
    ours and that ``max_pixels`` could not raise, and changing ``Image.MAX_IMAGE_PIXELS``
    instead would change it for the user's own Pillow calls too.
    """
    factory = {
        "PNG": PngImagePlugin.PngImageFile,
        "JPEG": JpegImagePlugin.jpeg_factory,
        "WEBP": WebPImagePlugin.WebPImageFile,
    }[fmt]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Corrupt EXIF data ...": Pillow's two lines; the pixels are fine
        im = factory(fp)
        try:
            w, h = im.size
            orientation = _exif_orientation(im) if fmt != "PNG" else 1
            if fmt == "PNG":
                im.verify()  # chunk CRCs: catches corruption and truncation without decoding
        finally:
            im.close()
    return w, h, orientation


def _exif_orientation(im: _PILImage.Image) -> int:
    """The EXIF orientation tag; 1 when absent or when the EXIF block is damaged (the pixels are fine)."""
    try:
        return int(im.getexif().get(0x0112, 1))
    except Exception:  # Pillow's EXIF parser raises many kinds on damaged blocks
        return 1


def _tiff_header(fp: IO[bytes]) -> tuple[int, int, int, bool]:
    """Width, height, orientation and "is white-is-zero" of a TIFF's first page (no pixel read).

    Pillow cannot open float RGB(A) TIFFs at all, which OpenCV decodes; tifffile (a
    dependency of scikit-image) reads the tags of any of them. Layouts that OpenCV decodes
    wrongly without a word (gray + alpha becomes 8-bit gray, CMYK comes back as BGRA, planar
    float and float16 are garbage or refused) are refused here with a message instead.
    """
    import tifffile

    log = logging.getLogger("tifffile")
    level = log.level
    # it logs damage to stderr ("contains no pages", "circular reference to IFD"), also while the
    # pages load lazily below; we raise instead
    log.setLevel(logging.CRITICAL)
    try:
        return _tiff_layout(tifffile.TiffFile(fp), fp.name)
    finally:
        log.setLevel(level)


def _tiff_layout(tf: Any, name: str) -> tuple[int, int, int, bool]:
    with tf:
        if not len(tf.pages):
            raise ImageReadError(f"path: {name} is a TIFF without any image in it")
        page = tf.pages.first
        photometric, spp = int(page.photometric), int(page.samplesperpixel)
        is_float = int(page.sampleformat) == 3
        layout = None
        if photometric not in (0, 1, 2, 3, 6):  # white/black-is-zero, RGB, palette, YCbCr
            layout = f"photometric {getattr(page.photometric, 'name', photometric)}"
        elif photometric in (0, 1) and spp != 1:
            layout = f"{spp} samples per gray pixel (gray + alpha)"
        elif is_float and int(page.bitspersample) not in (32, 64):
            layout = f"{page.bitspersample}-bit float samples"
        elif is_float and spp > 1 and int(page.planarconfig) != 1:
            layout = "float samples in separate planes"
        if layout is not None:
            raise ImageReadError(
                f"path: {name} is a TIFF with {layout}; expected gray, RGB or RGBA with 8- or"
                " 16-bit integer or 32-/64-bit float samples"
            )
        tag = page.tags.get(274)  # Orientation
        orientation = int(tag.value) if tag is not None else 1
        return int(page.imagewidth), int(page.imagelength), orientation, photometric == 0


def _header(path: Path, max_pixels: int) -> tuple[str, int, int, int, bool]:
    """Format, width, height, EXIF orientation (1–8) and whether 0 is white; pixel limit checked."""
    try:
        with open(path, "rb") as fp:
            fmt = _format(fp.read(16))
            fp.seek(0)
            if fmt is None:
                raise ImageReadError(f"path: {path} is {_other_format(path)}; expected PNG, JPEG, TIFF or WebP")
            w, h, orientation, inverted = _tiff_header(fp) if fmt == "TIFF" else (*_pillow_header(fp, fmt), False)
    except FileNotFoundError:
        raise ImageReadError(f"path: no such file: {path}") from None
    except IsADirectoryError:
        raise ImageReadError(f"path: {path} is a folder, not an image file") from None
    except PermissionError:
        raise ImageReadError(f"path: {path} cannot be read (permission denied)") from None
    except ImageReadError:
        raise
    except (OSError, SyntaxError, ValueError, struct.error, IndexError, KeyError, TypeError, EOFError) as e:
        why = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ImageReadError(f"path: {path} is not a readable {fmt} image ({why})") from None
    if w * h > max_pixels:
        raise ImageReadError(
            f"path: {path} is {w}×{h} = {w * h} pixels, over the limit of {max_pixels}"
            " (pass a larger max_pixels / --max-pixels if you trust this file)"
        )
    return str(fmt), w, h, orientation if 1 <= orientation <= 8 else 1, inverted


def stored_bit_depth(path: str | os.PathLike[str]) -> int:
    """Bits per sample an image file stores, from its header alone: 16 or 8.

    16 for a 16-bit PNG and for a TIFF of more than 8 bits per sample (16-bit or float), else
    8, also for a file that cannot be read (reading the image itself reports what is wrong
    with it). The command line uses it for ``--bit-depth``'s default, so that a 16-bit
    elevation model is not written back with a handful of levels.

    Parameters
    ----------
    path : str or os.PathLike
        An image file.

    Returns
    -------
    int
        16 or 8.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> with tempfile.TemporaryDirectory() as d:
    ...     f = os.path.join(d, "dem.png")
    ...     write_image(f, np.linspace(0, 1, 16, dtype=np.float32).reshape(4, 4), bit_depth=16)
    ...     stored_bit_depth(f)
    16
    """
    try:
        with open(path, "rb") as fp:
            head = fp.read(26)
            fmt = _format(head[:16])
            if fmt == "PNG":  # IHDR: the bit depth is byte 24
                return 16 if len(head) > 24 and head[24] == 16 else 8
            if fmt == "TIFF":
                import tifffile

                fp.seek(0)
                with tifffile.TiffFile(fp) as tf:
                    return 16 if len(tf.pages) and int(tf.pages.first.bitspersample) > 8 else 8
    except Exception:  # reading the image itself reports what is wrong with it
        return 8
    return 8


def _other_format(path: Path) -> str:
    """What a file we do not read is, for the message: 'a BMP file' or 'not an image'."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Pillow's bomb warning: we only want the name
            with _PILImage.open(path) as im:
                return f"a {im.format} file"
    except Exception:  # anything Pillow cannot identify is "not an image" to us
        return "not a readable image"


# In a scan's entropy-coded data, 0xFF is followed by 0x00 (a stuffed byte) or by a restart
# marker 0xD0–0xD7; any other byte after 0xFF is the marker that ends the scan.
_SCAN_END = re.compile(rb"\xff[^\x00\xd0-\xd7\xff]")


def _jpeg_complete(data: memoryview) -> bool:
    """Whether a JPEG stream reaches its end-of-image marker.

    Walks the marker segments by their lengths and each scan to the marker that ends it, so
    an EOI inside an EXIF thumbnail does not count and bytes after the real EOI (thumbnails,
    MPF images, padding that cameras write) do not matter.
    """
    n, pos = len(data), 2  # after SOI
    while pos + 1 < n:
        if data[pos] != 0xFF:  # extraneous bytes between segments: libjpeg skips them too
            nxt = bytes(data[pos:]).find(b"\xff")
            if nxt < 0:
                return False
            pos += nxt
            continue
        marker = data[pos + 1]
        if marker == 0xD9:
            return True
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if 0xD0 <= marker <= 0xD7 or marker == 0x01:  # standalone markers
            pos += 2
            continue
        if pos + 4 > n:
            return False
        pos += 2 + int.from_bytes(data[pos + 2 : pos + 4], "big")
        if marker == 0xDA:  # start of scan: the entropy-coded data runs to the next marker
            hit = _SCAN_END.search(data, pos)
            if hit is None:
                return False
            pos = hit.start()
    return False


def _orient(img: NDArray[Any], orientation: int) -> NDArray[Any]:
    """Apply an EXIF orientation (1–8) as Pillow's ``ImageOps.exif_transpose`` does."""
    if orientation in (2, 4, 5, 7):  # the mirrored ones: mirror first, then rotate as 1, 3, 6, 8
        img = img[:, ::-1]
    turns = {1: 0, 2: 0, 3: 2, 4: 2, 5: 1, 6: -1, 7: -1, 8: 1}[orientation]
    return np.rot90(img, turns) if turns else img


_stderr_lock = threading.Lock()
_stderr_users = 0
_stderr_saved = -1


@contextlib.contextmanager
def _c_stderr_dropped() -> Iterator[None]:
    """Send file descriptor 2 to the null device while C decoders run.

    libpng, libjpeg, libtiff and OpenCV print their own lines ("libpng error: Not enough
    image data", "[ERROR:0@...] imdecode_ ...") straight to it; a failed decode raises our
    one-line ImageReadError instead. Counted, so threads reading at the same time (the
    decoders release the GIL) share one redirection and the last one restores it.
    """
    global _stderr_users, _stderr_saved
    with _stderr_lock:
        if _stderr_users == 0:
            try:
                saved = os.dup(2)
            except OSError:  # no stderr at all: nothing to keep quiet
                saved = -1
            if saved >= 0:
                null = os.open(os.devnull, os.O_WRONLY)
                os.dup2(null, 2)
                os.close(null)
            _stderr_saved = saved
        _stderr_users += 1
    try:
        yield
    finally:
        with _stderr_lock:
            _stderr_users -= 1
            if _stderr_users == 0 and _stderr_saved >= 0:
                os.dup2(_stderr_saved, 2)
                os.close(_stderr_saved)
                _stderr_saved = -1


def _to_unit(img: NDArray[Any], path: Path) -> NDArray[np.float32]:
    """Samples as float32 in [0, 1]: integers by their range, floats as described in read_image."""
    out: NDArray[np.float32] = img.astype(np.float32)
    if img.dtype in (np.uint8, np.uint16):
        out /= np.float32(255.0 if img.dtype == np.uint8 else 65535.0)
        return out
    if not np.issubdtype(img.dtype, np.floating):
        raise ImageReadError(f"path: {path} has {img.dtype} samples; expected 8- or 16-bit unsigned integers or floats")
    finite = np.isfinite(out)
    if not finite.all():
        raise ImageReadError(
            f"path: {path} has {int(out.size - np.count_nonzero(finite))} NaN or infinite samples;"
            " expected finite values"
        )
    lo, hi = float(out.min()), float(out.max())
    if lo < 0.0 or hi > 1.0:
        warnings.warn(
            f"{path}: float samples span [{lo:.6g}, {hi:.6g}], outside [0, 1]; rescaled {lo:.6g}..{hi:.6g} to 0..1",
            RescaledImageWarning,
            stacklevel=3,
        )
        out = (out - np.float32(lo)) / np.float32(hi - lo) if hi > lo else np.zeros_like(out)
        np.clip(out, 0.0, 1.0, out=out)  # float32 rounding can leave 1 + eps
    return out


def image_size(path: str | os.PathLike[str], *, max_pixels: int = DEFAULT_MAX_PIXELS) -> tuple[int, int]:
    """``(H, W)`` of the image :func:`read_image` would return, from the file's header alone
    (EXIF orientation applied, ``max_pixels`` checked), without decoding it.

    Raises
    ------
    ImageReadError
        As :func:`read_image` for a missing, unreadable or too large file.

    Examples
    --------
    >>> import phloem, tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "bark.png")
    >>> phloem.io.write_image(path, phloem.data.bark()[:100])
    >>> phloem.io.image_size(path)
    (100, 256)
    """
    if int(max_pixels) < 1:
        raise ValueError(f"max_pixels: expected a positive pixel count, got {max_pixels}")
    _, w, h, orientation, _ = _header(Path(path), int(max_pixels))
    return (w, h) if orientation >= 5 else (h, w)  # orientations 5–8 turn the image a quarter


def read_image(path: str | os.PathLike[str], *, max_pixels: int = DEFAULT_MAX_PIXELS) -> NDArray[np.float32]:
    """Read an image file as a float32 array in [0, 1].

    The size in the header is checked against ``max_pixels`` before anything is decoded. An
    EXIF orientation (1–8, as cameras write it) is applied, so the array is upright the way
    viewers and Pillow's ``ImageOps.exif_transpose`` show it.

    Parameters
    ----------
    path : str or path-like
        A PNG, JPEG, TIFF or WebP file, gray, RGB or RGBA. Integer samples must have 8 or 16
        bits and are divided by 255 or 65535. Float samples (TIFF, 32 or 64 bits) in [0, 1]
        are taken as they are; a float image with values outside [0, 1] is rescaled from its
        min..max to [0, 1] (all channels together), with a :class:`RescaledImageWarning`
        naming the range found. NaN or infinite samples are refused.
    max_pixels : int, optional
        Refuse images with more pixels than this (default :data:`DEFAULT_MAX_PIXELS`). This
        is the only limit: Pillow's own decompression-bomb ceiling is not applied. OpenCV,
        which decodes, stops at 2**30 pixels.

    Returns
    -------
    image : (M, N) or (M, N, C) ndarray of float32
        Gray images are 2-D; colour images are RGB or RGBA, in that order.

    Raises
    ------
    ImageReadError
        If the file is missing, not an image, corrupt, truncated, over ``max_pixels`` or has
        NaN or infinite samples.

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
    fmt, w, h, orientation, inverted = _header(p, int(max_pixels))
    raw = np.fromfile(p, dtype=np.uint8)
    if fmt == "JPEG" and not _jpeg_complete(raw.data):
        raise ImageReadError(f"path: {p} is a truncated JPEG (the data ends before the end-of-image marker)")
    if w * h > _CV2_MAX_PIXELS:
        raise ImageReadError(f"path: {p} is {w}×{h} = {w * h} pixels; the decoder (OpenCV) reads at most 2**30")
    with _c_stderr_dropped():
        try:
            img = cv2.imdecode(raw, cv2.IMREAD_UNCHANGED)
        except cv2.error:
            img = None
    if img is None or img.shape[0] != h or img.shape[1] != w:
        raise ImageReadError(f"path: {p} could not be decoded as a {fmt} image (corrupt or truncated)")
    out = _to_unit(img, p)
    if inverted:  # photometric white-is-zero: OpenCV hands over the stored samples
        out = np.float32(1.0) - out
    if out.ndim == 3:
        if out.shape[2] == 3:
            out = out[:, :, ::-1]
        elif out.shape[2] == 4:
            out = out[:, :, [2, 1, 0, 3]]
    if orientation != 1:
        out = _orient(out, orientation)
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


#: Version of the sidecar layout (``docs/replay.md``). Sidecars without the field are version 1:
#: the same keys less ``threads``, ``inputs`` and ``details``, with details mixed into ``parameters``.
SIDECAR_VERSION = 2


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The JSON sidecar of an output file or folder: ``out.png`` → ``out.png.json``, a JSON output
    ``skel.json`` → ``skel.sidecar.json`` (not ``skel.json.json``), a folder ``model`` → ``model.json``.

    The one rule every writer of sidecars follows; :func:`find_sidecar` also finds the older name
    of a JSON output's sidecar.

    Examples
    --------
    >>> from phloem.io import sidecar_path
    >>> sidecar_path("out/bark.png").name, sidecar_path("river.json").name, sidecar_path("model").name
    ('bark.png.json', 'river.sidecar.json', 'model.json')
    """
    p = Path(path)
    if p.suffix.lower() == ".json":
        return p.with_name(p.name[: -len(p.suffix)] + ".sidecar.json")
    return p.with_name(p.name + ".json")


def find_sidecar(path: str | os.PathLike[str]) -> Path | None:
    """The existing sidecar of an output: :func:`sidecar_path`, else the ``X.json.json`` name that
    JSON outputs had before sidecar version 2; None when there is neither."""
    p = Path(path)
    for side in (sidecar_path(p), p.with_name(p.name + ".json")):
        if side != p and side.is_file():
            return side
    return None


def file_digest(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file's bytes, or of a folder: every file under it by its relative path,
    in sorted order, so a renamed, added, removed or edited file changes it.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "a.txt"
    >>> _ = path.write_text("abc")
    >>> file_digest(path)[:16]
    'ba7816bf8f01cfea'
    """
    p = Path(path)
    if p.is_dir():
        h = hashlib.sha256()
        for f in sorted(q for q in p.rglob("*") if q.is_file()):
            h.update(f"{f.relative_to(p).as_posix()}\0{file_digest(f)}\n".encode())
        return h.hexdigest()
    st = p.stat()
    # a batch worker hashes the same inputs for every item's sidecar; a file whose inode, size,
    # mtime and ctime (which no one can set back) are unchanged still has its bytes
    key = (str(p.absolute()), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    known = _digests.get(key)
    if known is not None:
        return known
    h = hashlib.sha256()
    with open(p, "rb") as fp:
        for block in iter(lambda: fp.read(1 << 20), b""):
            h.update(block)
    if len(_digests) >= 4096:
        _digests.clear()
    digest = _digests[key] = h.hexdigest()
    return digest


_digests: dict[tuple[Any, ...], str] = {}


def _sidecar(
    path: Path,
    command: str,
    parameters: Mapping[str, Any],
    seed: int | None,
    default: Any = None,
    *,
    threads: int | None = None,
    inputs: Mapping[str, str] | None = None,
    details: Mapping[str, Any] | None = None,
) -> bytes:
    """The bytes of ``path``'s sidecar (layout :data:`SIDECAR_VERSION`, ``docs/replay.md``)."""
    from . import __version__, _core

    meta = {
        "sidecar_version": SIDECAR_VERSION,
        "phloem_version": __version__,
        "command": command,
        "seed": seed,
        "threads": _core.default_threads() if threads is None else int(threads),
        "parameters": {k: (str(v) if isinstance(v, os.PathLike) else v) for k, v in parameters.items()},
        "inputs": [{"path": f, "sha256": digest} for f, digest in (inputs or {}).items()],
        "details": dict(details or {}),
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
    threads: int | None = None,
    inputs: Sequence[str | os.PathLike[str]] = (),
    details: Mapping[str, Any] | None = None,
) -> Path:
    """Write an output image and its sidecar (``docs/replay.md``): the command, its parameters,
    the seed, the thread count (None: the default pool's), the SHA-256 of each of ``inputs``,
    ``details`` of the result and the phloem version.

    Both targets are checked before either is written, and both take their names together, so
    a refused overwrite or a failed write (a full disk) leaves neither behind. Returns the
    sidecar's path.
    """
    p = Path(path)
    side = sidecar_path(p)
    data = encode(p, image, bit_depth)
    digests = {str(f): file_digest(f) for f in inputs}
    with Transaction(overwrite) as tx:
        tx.reserve(p)
        tx.reserve(side)
        tx.stage(p, data)
        tx.stage(side, _sidecar(p, command, parameters, seed, threads=threads, inputs=digests, details=details))
        tx.commit()
    return side
