"""Writing output files: encoding, atomic creation without silent overwrite, target checks.

Shared by ``phloem.io`` and the command line, which must write several files of one run.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import re
import secrets
import stat
import tempfile
import time
import zipfile
from collections.abc import Mapping
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


class OutputError(OSError):
    """An output file that cannot be written, in one line that names it."""


def _oserror(path: Path, e: OSError, what: str = "") -> OutputError:
    err = OutputError(f"out: cannot write {what or path}: {e.strerror or e}")
    err.errno = e.errno  # so callers can still tell a full disk (ENOSPC) from a read-only one (EROFS)
    return err


# Hidden temporaries of our own: ``.NAME.PID.XXXXXXXX.tmp`` (mkstemp's 8 random characters). The
# pid says whether the writer still runs; the older pid-less form of earlier versions is matched too.
_RANDOM = r"[a-z0-9_]{8}"
#: A temporary whose writer's pid is alive is left alone unless it is this old (s): the pid may
#: belong to another process by now. Staging writes a file in well under this.
STALE_AFTER_S = 3600.0
#: The older form has no pid; a writer of it held its temporary for a fraction of a second.
STALE_OLD_FORM_AFTER_S = 60.0


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it exists, owned by someone else
        pass
    # a killed writer whose parent died too can stay a zombie where nothing reaps orphans
    # (CI containers): it answers signal 0 but writes nothing more
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True
    return state not in ("Z", "X")


def remove_stale_temporaries(path: Path) -> list[Path]:
    """Remove hidden temporaries of our own naming for ``path`` that a killed run left behind.

    Only names of the exact form this module makes for this very target are considered, and of
    those only ones whose writer is gone (pid dead, not ours) or that are older than
    :data:`STALE_AFTER_S`, so neither a user's file nor a running writer's temporary is touched.
    """
    folder = path.parent
    new_form = re.compile(rf"\.{re.escape(path.name)}\.(\d+)\.{_RANDOM}\.tmp")
    old_form = re.compile(rf"\.{re.escape(path.name)}\.{_RANDOM}\.tmp")
    removed: list[Path] = []
    try:
        names = [n for n in os.listdir(folder) if n.startswith(f".{path.name}.") and n.endswith(".tmp")]
    except OSError:
        return removed
    now = time.time()
    for name in names:
        tmp = folder / name
        try:
            st = tmp.lstat()
        except OSError:
            continue
        if not stat.S_ISREG(st.st_mode):
            continue
        age = now - st.st_mtime
        m = new_form.fullmatch(name)
        if m is not None:
            pid = int(m.group(1))
            stale = pid != os.getpid() and (not _pid_alive(pid) or age > STALE_AFTER_S)
        else:
            stale = old_form.fullmatch(name) is not None and age > STALE_OLD_FORM_AFTER_S
        if stale:
            try:
                tmp.unlink()
                removed.append(tmp)
            except OSError:
                pass
    return removed


_PROBE = "phloem-probe"


def _probe(folder: Path) -> None:
    """Create and remove a temporary in ``folder``: read-only folders and file systems fail here
    (permission bits alone say nothing to root)."""
    remove_stale_temporaries(folder / _PROBE)  # a run killed between the two steps
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{_PROBE}.{os.getpid()}.", suffix=".tmp", dir=folder)
    except OSError as e:
        if e.errno == errno.ENOENT:  # /proc: the folder exists but takes no new files
            e = OSError(e.errno, "it takes no new files")
        raise _oserror(folder, e, f"into folder {folder}") from None
    os.close(fd)
    os.unlink(tmp)


def _existing_ancestor(folder: Path) -> Path:
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


# errnos of os.link on file systems without hard links; then os.replace, after an existence check
_NO_LINKS = {errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EXDEV, errno.EMLINK, errno.ENOSYS}


class Transaction:
    """Several output files written together: all of them or none.

    :meth:`reserve` checks a target before the computation (folder, writability, an existing
    file or folder, two outputs of one name); :meth:`stage` writes its bytes to a hidden
    temporary beside it; :meth:`commit` moves every temporary into place, and only then. Any
    failure in between, or :meth:`rollback`, removes every temporary and every file this
    transaction had already put in place, and nothing else. Without ``overwrite`` an existing
    file is never replaced (``os.link`` fails atomically if the name exists); with it, replaced
    files are kept as hard-link backups until the commit has succeeded, so a failed commit puts
    them back.

    Use it as a context manager: leaving the block by an exception rolls back.
    """

    def __init__(self, overwrite: bool = False, *, make_folders: bool = False) -> None:
        self.overwrite = overwrite
        self.make_folders = make_folders
        self._reserved: dict[Path, Path] = {}  # resolved -> as given
        self._staged: list[tuple[Path, Path]] = []  # (temporary, target)
        self._created_folders: list[Path] = []
        self._probed: set[Path] = set()
        self._committed = False
        self.notes: list[str] = []

    def __enter__(self) -> Transaction:
        return self

    def __exit__(self, kind: object, value: object, tb: object) -> None:
        if not self._committed:
            self.rollback()

    # -- before the computation -------------------------------------------------------------
    def reserve(self, path: str | os.PathLike[str]) -> Path:
        """Check that ``path`` can be written by this transaction; raise the one-line reason if not."""
        p = Path(path)
        key = _key(p)
        if key in self._reserved:
            raise ValueError(f"out: {p} is named for two outputs of this command; they must be different files")
        if p.name in ("", ".", ".."):
            raise ValueError(f"out: expected a file name, got {str(p)!r}")
        folder = p.parent
        if folder.exists() and not folder.is_dir():
            raise ValueError(f"out: {folder} is not a folder")
        if not folder.exists():
            if not self.make_folders:
                raise FileNotFoundError(f"out: folder {folder} does not exist")
            folder = _existing_ancestor(folder)
            if not folder.is_dir():
                raise ValueError(f"out: {folder} is not a folder")
        if p.is_dir():
            raise IsADirectoryError(f"out: {p} is a folder; expected a file name")
        if (p.exists() or p.is_symlink()) and not self.overwrite:
            raise FileExistsError(f"out: {p} already exists (pass overwrite=True / --force to replace it)")
        if folder not in self._probed:
            _probe(folder)
            self._probed.add(folder)
        remove_stale_temporaries(p)
        self._reserved[key] = p
        return p

    # -- after it ----------------------------------------------------------------------------
    def _folder(self, folder: Path) -> None:
        if folder.is_dir() or not self.make_folders:
            return
        missing = []
        f = folder
        while not f.exists() and f != f.parent:
            missing.append(f)
            f = f.parent
        for f in reversed(missing):
            os.mkdir(f)
            self._created_folders.append(f)

    def stage(self, path: str | os.PathLike[str], data: bytes) -> None:
        """Write ``data`` to a hidden temporary beside ``path``; it takes the name at :meth:`commit`."""
        p = Path(path)
        key = _key(p)
        if key not in self._reserved:
            self.reserve(p)
        if any(_key(t) == key for _tmp, t in self._staged):
            raise ValueError(f"out: {p} is named for two outputs of this command; they must be different files")
        try:
            self._folder(p.parent)
            fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.{os.getpid()}.", suffix=".tmp", dir=p.parent)
        except OSError as e:
            raise _oserror(p, e) from None
        self._staged.append((Path(tmp), p))
        try:
            # mkstemp makes the file private (0600); an output file gets the usual umask mode.
            os.fchmod(fd, 0o666 & ~umask())
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        except OSError as e:
            raise _oserror(p, e) from None
        finally:
            os.close(fd)

    def commit(self) -> None:
        """Give every staged file its name; on any failure undo what was done and raise."""
        placed: list[tuple[Path, Path | None]] = []  # (target, backup of the file it replaced)
        try:
            for tmp, p in self._staged:
                placed.append((p, self._place(tmp, p)))
        except BaseException:
            for p, backup in reversed(placed):
                try:
                    if backup is not None:
                        os.replace(backup, p)
                    else:
                        os.unlink(p)
                except OSError:
                    pass
            self.rollback()
            raise
        for _p, backup in placed:
            if backup is not None:
                _unlink(backup)
        for tmp, _p in self._staged:
            _unlink(tmp)
        self._staged.clear()
        self._committed = True

    def _place(self, tmp: Path, p: Path) -> Path | None:
        if self.overwrite:
            backup = None
            if p.is_file() and not p.is_symlink():
                backup = p.parent / f".{p.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
                try:
                    os.link(p, backup)
                except OSError:
                    backup = None
            try:
                os.replace(tmp, p)
            except OSError as e:
                if backup is not None:
                    _unlink(backup)
                raise _oserror(p, e) from None
            return backup
        try:
            os.link(tmp, p)  # fails atomically if p exists
        except FileExistsError:
            raise FileExistsError(f"out: {p} already exists (pass overwrite=True / --force to replace it)") from None
        except OSError as e:
            if e.errno not in _NO_LINKS:
                raise _oserror(p, e) from None
            if p.exists():
                raise FileExistsError(f"out: {p} already exists (pass overwrite=True / --force)") from None
            try:
                os.replace(tmp, p)
            except OSError as e2:
                raise _oserror(p, e2) from None
        return None

    def rollback(self) -> None:
        """Remove every temporary, and every folder this transaction made that is still empty."""
        for tmp, _p in self._staged:
            _unlink(tmp)
        self._staged.clear()
        for f in reversed(self._created_folders):
            with contextlib.suppress(OSError):
                os.rmdir(f)
        self._created_folders.clear()


def _key(p: Path) -> Path:
    """One spelling per file, whether or not it exists yet (``a/../o.png`` is ``o.png``)."""
    return Path(os.path.abspath(p.parent)).resolve() / p.name


def _unlink(path: Path) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


def atomic_write(path: Path, data: bytes, overwrite: bool) -> None:
    """One file, all or nothing (a :class:`Transaction` of one)."""
    with Transaction(overwrite) as tx:
        tx.stage(path, data)
        tx.commit()


def check_target(path: Path, overwrite: bool) -> None:
    Transaction(overwrite).reserve(path)


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


def npz_bytes(arrays: Mapping[str, Any]) -> bytes:
    """An ``.npz`` of ``arrays`` (no pickles), deflated at level 1: saved models are large, and
    level 6 is much slower for little gain (docs/pipelines/leaves/analysis.md)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        for name, a in arrays.items():
            with z.open(f"{name}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.ascontiguousarray(a), allow_pickle=False)
    return buf.getvalue()


def write_folder(path: str | os.PathLike[str], files: Mapping[str, bytes], overwrite: bool) -> None:
    """The files of a saved model (name → bytes) into the folder ``path``, made if missing:
    all of them or none; an existing file is replaced only with ``overwrite``."""
    folder = Path(path)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"path: {folder} exists and is not a folder")
    with Transaction(overwrite, make_folders=True) as tx:
        for name in files:
            tx.reserve(folder / name)
        for name, data in files.items():
            tx.stage(folder / name, data)
        tx.commit()
