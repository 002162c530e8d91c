"""Atomic file writes (pure Python/numpy): a reader sees the old file or the new one, never a torn one.

Every helper writes into a temporary file in the destination's directory (same file system), flushes and
``fsync``s it, then ``os.replace``s it over the destination and ``fsync``s the directory. If anything fails
(an exception, a full disk, a failing ``os.replace``) the temporary file is removed and the destination is left
as it was; an ``OSError`` (e.g. ``No space left on device``) is re-raised naming the destination file. A
process killed mid-write leaves at most a hidden ``.<name>.tmp-*`` file beside the destination, never a partial
destination.

Use :func:`atomic_path` for writers that need a file name (OpenEXR, PNG): it yields a temporary path with the
destination's suffix and moves it into place when the block succeeds.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import secrets
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from mincam_sim.errors import StoreError

TMP_MARK = ".tmp-"
#: What numpy says, without an errno, when the disk takes only part of an array (``ndarray.tofile``, ``np.save``)
_SHORT_WRITE = re.compile(r"\d+ requested and \d+ written")


def _tmp_name(path: Path) -> Path:
    return path.with_name(f".{path.name}{TMP_MARK}{os.getpid()}-{secrets.token_hex(4)}{path.suffix}")


def fsync_dir(directory: str | Path) -> None:
    """``fsync`` a directory so a rename inside it is durable (no-op where directories cannot be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _remove_quietly(path: Path) -> None:
    with contextlib.suppress(OSError):
        path.unlink()


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; when the block succeeds, move it over ``path`` atomically.

    Parameters
    ----------
    path : str or Path
        Destination file. Its parent directory is created if needed.

    Yields
    ------
    Path
        Where to write (same directory and suffix as ``path``). The caller writes and closes the file there.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_name(path)
    try:
        yield tmp
        if tmp.exists():
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as err:
        _remove_quietly(tmp)
        raise _naming(err, path) from err
    except RuntimeError as err:
        _remove_quietly(tmp)
        if tmp.name not in str(err):
            raise
        raise _writer_failure(err, tmp, path) from err
    except BaseException:
        _remove_quietly(tmp)
        raise
    fsync_dir(path.parent)


def _writer_failure(err: RuntimeError, tmp: Path, path: Path) -> OSError:
    """A C++ writer's RuntimeError about the temporary file (OpenEXR: "Failed to write ... File too large") as
    an ``OSError`` naming the destination, with the errno its text implies (ENOSPC, EFBIG, else EIO)."""
    import errno

    text = " ".join(str(err).replace(str(tmp), str(path)).replace(tmp.name, path.name).split())
    code = errno.ENOSPC if "space" in text.lower() else errno.EFBIG if "too large" in text.lower() else errno.EIO
    strerror = os.strerror(code) if code != errno.EIO else f"cannot write the file ({text})"
    return OSError(code, strerror, str(path))


def _naming(err: OSError, path: Path) -> OSError:
    """``err`` naming the destination ``path`` (not the hidden temporary) as the file that failed.

    A full disk (``ENOSPC``) raised by ``write`` carries no file name, and one raised by ``open`` names the
    temporary file; either way the user is told which output could not be written.
    """
    named = err.filename
    if err.errno is None and _SHORT_WRITE.fullmatch(str(err)):  # numpy's tofile: a write the disk cut short
        return OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)} (only part of the file could be written: "
                       f"{' '.join(str(err).split())})", str(path))
    if named is not None and TMP_MARK not in Path(str(named)).name:
        return err
    strerror = err.strerror or str(err) or type(err).__name__
    return OSError(err.errno, strerror, str(path))


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "wb", encoding: str | None = None) -> Iterator[IO[Any]]:
    """Open a temporary file for writing; on success flush, fsync and move it over ``path``.

    Parameters
    ----------
    path : str or Path
        Destination file.
    mode : {"wb", "w"}
        Binary or text.
    encoding : str, optional
        Text encoding (``"utf-8"`` if ``mode`` is ``"w"`` and none is given).
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_open writes new files only: mode must be 'wb' or 'w', got {mode!r}")
    if mode == "w" and encoding is None:
        encoding = "utf-8"
    with atomic_path(path) as tmp, open(tmp, mode, encoding=encoding) as fh:
        yield fh
        fh.flush()
        os.fsync(fh.fileno())


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return ``path``."""
    with atomic_open(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def atomic_write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically; return ``path``."""
    return atomic_write_bytes(path, text.encode(encoding))


def atomic_write_json(path: str | Path, obj: Any, **dumps_kw: Any) -> Path:
    """Write ``json.dumps(obj, **dumps_kw)`` to ``path`` atomically; return ``path``."""
    return atomic_write_text(path, json.dumps(obj, **dumps_kw) + "\n")


def atomic_save_npy(path: str | Path, array: np.ndarray) -> Path:
    """``numpy.save`` to ``path`` atomically (no pickles); return ``path``."""
    with atomic_open(path, "wb") as fh:
        np.save(fh, np.asanyarray(array), allow_pickle=False)
    return Path(path)


def atomic_save_npz(path: str | Path, compressed: bool = False, **arrays: Any) -> Path:
    """``numpy.savez`` (or ``savez_compressed``) to ``path`` atomically; return ``path``.

    The name is used as given (numpy appends ``.npz`` to bare names; this does not).
    """
    with atomic_open(path, "wb") as fh:
        (np.savez_compressed if compressed else np.savez)(fh, **arrays)
    return Path(path)


def leftover_temporaries(directory: str | Path) -> list[Path]:
    """Temporary files left in ``directory`` by writes that were killed (safe to delete)."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    return sorted(p for p in directory.iterdir() if p.name.startswith(".") and TMP_MARK in p.name)


def remove_files(paths: Iterable[Path], why: str = "", fix: str = "") -> list[Path]:
    """Delete those of ``paths`` that are files (or links) and ``fsync`` their folders; return those deleted.

    Raises
    ------
    StoreError
        A file that cannot be deleted, named with ``why`` (what it is) and ``fix`` (what to do).
    """
    removed = []
    for path in map(Path, paths):
        if not (path.is_file() or path.is_symlink()):
            continue
        try:
            path.unlink()
        except FileNotFoundError:
            continue
        except OSError as err:
            raise StoreError(f"cannot delete {path}{f' ({why})' if why else ''}: {err.strerror or err}"
                             f"{f'; {fix}' if fix else ''}") from None
        removed.append(path)
    for folder in sorted({path.parent for path in removed}):
        fsync_dir(folder)
    return removed


__all__ = [
    "atomic_open",
    "atomic_path",
    "atomic_save_npy",
    "atomic_save_npz",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "fsync_dir",
    "leftover_temporaries",
    "remove_files",
]
