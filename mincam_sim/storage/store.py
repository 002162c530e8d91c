"""Resumable, verified on-disk results and caches (pure numpy).

:class:`ResultStore` -- a run directory holds ``values.npy`` and ``stderr.npy`` (memory-mapped, one row per
frame, NaN until computed), ``done.npy`` (bool per frame) and ``run.json`` (the run's full identity and its
key). Rows are flushed as soon as they are computed; memory-mapped pages belong to the operating system, so a
killed process loses at most the frame in progress. Reopening with the same identity resumes; a different
identity is refused with :class:`~mincam_sim.errors.StaleResultError`, naming what changed; ``overwrite=True``
starts afresh. ``run.json`` is written last and atomically: it is the commit mark of a store. A torn or foreign
file is reported with :class:`~mincam_sim.errors.StoreError` naming the file and what to do. While a store is
open its directory is locked (``.mincam.lock``): another process gets
:class:`~mincam_sim.errors.OutDirLockedError` naming the holder's PID.

:class:`ContentCache` -- a directory of content-addressed ``<key>.npz`` files, written atomically and verified
when read (the key and a digest of the arrays are stored inside); a torn or mismatched file is ignored with a
warning and recomputed.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import socket
import threading
import warnings
import weakref
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mincam_sim.errors import OutDirLockedError, StaleResultError, StoreError
from mincam_sim.measurements import json_default
from mincam_sim.storage.atomic import atomic_open, atomic_path, atomic_write_json, remove_files
from mincam_sim.storage.identity import canonical, diff_identities, fingerprint, run_key

STORE_FORMAT = "mincam_sim.result_store"
STORE_VERSION = 2
STORE_FILES = ("run.json", "values.npy", "stderr.npy", "done.npy")
LOCK_NAME = ".mincam.lock"
ENV_CACHE_DIR = "MINCAM_CACHE_DIR"

_HINT = "delete the directory or rerun with --overwrite (overwrite=True) to start afresh"


# ----------------------------------------------------------------------------------------------------- locks


_held_lock = threading.Lock()
# directory (resolved) -> the DirLock this process holds on it (weak: a lock nobody references is released)
_held: weakref.WeakValueDictionary[str, DirLock] = weakref.WeakValueDictionary()


class DirLock:
    """An exclusive, advisory lock on a directory (``flock`` on ``<dir>/.mincam.lock``).

    The lock file records the holder's PID and host, so a refused process can name it. The lock is released by
    :meth:`release`, when the object is garbage-collected, or by the operating system when the process ends
    (even if killed). Within one process a newer lock on the same directory takes over from an older one, which
    is marked ``superseded`` (its owner's writes then fail instead of interleaving): an interrupted run
    whose objects are still referenced (say, by a traceback) does not block its own rerun. A run holds one lock,
    on its top directory, for every store inside it; so a directory inside one that another process holds
    locked is refused as well.

    Parameters
    ----------
    directory : str or Path
        An existing directory.
    what : str
        Shown in the refusal message (``"output directory"``).

    Raises
    ------
    OutDirLockedError
        Another process holds the lock.
    StoreError
        The lock file cannot be created.
    """

    def __init__(self, directory: str | Path, what: str = "output directory") -> None:
        self.directory = Path(directory)
        self.path = self.directory / LOCK_NAME
        self.superseded = False
        self._fd: int | None = None
        self._real = os.path.realpath(self.directory)
        with _held_lock:
            previous = _held.get(self._real)
            if previous is not None and previous._fd is not None and previous._pid == os.getpid():
                fd = previous._fd  # take over this process's own lock
                previous._finalizer.detach()
                previous._fd = None
                previous.superseded = True
            else:
                self._check_ancestors(what)
                fd = self._acquire(what)
            self._fd, self._pid = fd, os.getpid()
            self._finalizer = weakref.finalize(self, _close_quietly, fd)
            _held[self._real] = self
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()} {socket.gethostname()}\n".encode(), 0)

    def _check_ancestors(self, what: str) -> None:
        """Refuse a directory inside one that another process holds locked (a run's one lock covers its stores);
        folders above that this process holds are fine."""
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX: no locking
            return
        for parent in Path(self._real).parents:
            path = parent / LOCK_NAME
            held = _held.get(str(parent))
            if (held is not None and held._fd is not None and held._pid == os.getpid()) or not path.is_file():
                continue
            try:
                fd = os.open(path, os.O_RDONLY)
            except OSError:
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)  # free unless another process holds it
            except OSError:
                raise OutDirLockedError(
                    f"{what} {self.directory} is inside {parent}, in use by another run ({_read_holder(fd)}); wait "
                    "for it to finish, stop it, or choose another output directory") from None
            finally:
                os.close(fd)

    def _acquire(self, what: str) -> int:
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as err:
            raise StoreError(f"cannot create the lock file {self.path}: {err.strerror or err}; "
                             f"check that the {what} is writable") from None
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX: no locking
            return fd
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            holder = _read_holder(fd)
            os.close(fd)
            if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise OutDirLockedError(
                    f"{what} {self.directory} is in use by another run ({holder}); wait for it to finish, stop "
                    "it, or choose another output directory"
                ) from None
            raise StoreError(f"cannot lock {self.path}: {err.strerror or err}") from None
        return fd

    @property
    def held(self) -> bool:
        """True while this object holds the lock."""
        return self._fd is not None

    def release(self) -> None:
        """Release the lock (idempotent; a superseded lock has nothing to release)."""
        with _held_lock:
            if self._fd is None:
                return
            self._fd = None
            if _held.get(self._real) is self:
                del _held[self._real]
            self._finalizer()

    def __enter__(self) -> DirLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _read_holder(fd: int) -> str:
    try:
        text = os.pread(fd, 200, 0).decode(errors="replace").split()
    except OSError:
        text = []
    if text and text[0].isdigit():
        host = f" on {text[1]}" if len(text) > 1 and text[1] != socket.gethostname() else ""
        return f"PID {text[0]}{host}"
    return "PID unknown"


def _close_quietly(fd: int) -> None:
    # Closing the descriptor releases the flock.
    with contextlib.suppress(OSError):
        os.close(fd)


# ------------------------------------------------------------------------------------------ result store


def _ensure_directory(directory: Path) -> None:
    if directory.exists() and not directory.is_dir():
        raise StoreError(f"output directory {directory} is an existing file; choose a directory path")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise StoreError(f"cannot create output directory {directory}: {err.strerror or err}") from None


def _check_npy(path: Path, shape: tuple[int, ...], dtype: np.dtype) -> None:
    """Raise StoreError unless ``path`` is a complete .npy of ``shape`` and ``dtype`` (checked on the header)."""
    where = f"{path.name} in {path.parent}"
    if not path.is_file():
        raise StoreError(f"{where} is missing (a torn or partial result store); {_HINT}")
    size = path.stat().st_size
    if size == 0:
        raise StoreError(f"{where} is empty (0 bytes: a run was killed while creating it?); {_HINT}")
    try:
        with open(path, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                header = np.lib.format.read_array_header_1_0(fh)
            elif version == (2, 0):
                header = np.lib.format.read_array_header_2_0(fh)
            else:
                raise ValueError(f"unsupported .npy version {version}")
            offset = fh.tell()
    except (ValueError, OSError, EOFError, SyntaxError) as err:
        raise StoreError(f"{where} is not a readable .npy array ({err}); {_HINT}") from None
    got_shape, fortran, got_dtype = header
    if fortran or tuple(got_shape) != tuple(shape) or np.dtype(got_dtype) != np.dtype(dtype):
        raise StoreError(
            f"{where} holds a {np.dtype(got_dtype)} array of shape {tuple(got_shape)} but this store needs "
            f"{np.dtype(dtype)} {tuple(shape)}; {_HINT}"
        )
    expected = offset + int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    if size != expected:
        raise StoreError(f"{where} is truncated or padded ({size} bytes, expected {expected}); {_HINT}")


def _read_run_json(path: Path) -> dict:
    where = f"{path.name} in {path.parent}"
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise StoreError(f"cannot read {where}: {err.strerror or err}") from None
    if not raw.strip():
        raise StoreError(f"{where} is empty (a run was killed while writing it?); {_HINT}")
    try:
        info = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise StoreError(f"{where} is not valid JSON ({err}); the store is torn: {_HINT}") from None
    if not isinstance(info, dict):
        raise StoreError(f"{where} is not a mincam_sim result store (a JSON {type(info).__name__}); "
                         "choose another output directory or delete it")
    if info.get("format") != STORE_FORMAT:
        if "key" in info and "shape" in info:
            raise StaleResultError(
                f"{path.parent} holds results of a different run, written by an older mincam_sim that did not "
                f"record their content, so they cannot be verified; {_HINT}"
            )
        raise StoreError(f"{where} was not written by mincam_sim's result store; choose another output directory "
                         "or delete it")
    if info.get("version") != STORE_VERSION or not isinstance(info.get("key"), str):
        raise StoreError(f"{where} has store version {info.get('version')!r} (this mincam_sim writes "
                         f"{STORE_VERSION}); {_HINT}")
    return info


def _summary(parts: list[str], limit: int = 6) -> str:
    shown = parts[:limit]
    more = f" and {len(parts) - limit} more" if len(parts) > limit else ""
    return ", ".join(shown) + more


def _refuse_different_run(directory: Path, old: dict, new: dict) -> None:
    """Raise the one refusal of a store that holds another run, naming what changed between ``old`` and ``new``."""
    changed = [c.removeprefix("identity.") for c in diff_identities(old, new, depth=3)]
    what = _summary(changed) if changed else "its identity key"
    raise StaleResultError(
        f"{directory} holds results of a different run (changed: {what}); rerun with --overwrite "
        "(overwrite=True) to replace them, or choose another output directory"
    )


class ResultStore:
    """Per-frame results of shape (n_frames, n_columns), written incrementally, verified on reopening.

    Parameters
    ----------
    directory : str or Path
        Run directory (created if needed). Locked while the store is open.
    n_frames : int
        Number of rows.
    columns : list of str
        Column names (e.g. mixel names).
    identity : dict
        Everything that determines the numbers (content fingerprints, budget, seed, form, versions ...):
        anything :func:`~mincam_sim.storage.identity.canonical` accepts. Stored in ``run.json`` in canonical form.
    overwrite : bool
        Delete the store files already there (of any run) and start afresh.
    lock : bool or DirLock
        True: lock the directory against other processes while the store is open. A held :class:`DirLock` on
        the directory or a folder above it: the caller's lock (a run's), which the store checks, uses and leaves
        held (no second lock file). False: no lock.

    Attributes
    ----------
    values, stderr : (n_frames, n_columns) memory-mapped float64 arrays (NaN until written)
    done : (n_frames,) memory-mapped bool array
    key : str
        Fingerprint of the identity, ``n_frames`` and ``columns``.
    resumed : bool
        True when results of an earlier run with the same identity were found.

    Raises
    ------
    StaleResultError
        The directory holds results of a different run (the message names what changed).
    StoreError
        A store file is torn, truncated, foreign or unreadable; the directory cannot be created.
    OutDirLockedError
        Another process holds the directory.
    """

    def __init__(
        self,
        directory: str | Path,
        n_frames: int,
        columns: Sequence[str],
        identity: Any,
        overwrite: bool = False,
        lock: bool | DirLock = True,
    ) -> None:
        self.directory = Path(directory)
        self.columns = [str(c) for c in columns]
        self.shape = (int(n_frames), len(self.columns))
        self.identity = canonical(identity)
        self.key = run_key({"identity": self.identity, "n_frames": self.shape[0], "columns": self.columns})
        self.resumed = False
        self._lock: DirLock | None = None
        self._own_lock = False
        if isinstance(lock, DirLock):
            _check_covers(lock, self.directory)
            self._lock = lock
        _ensure_directory(self.directory)
        if lock is True:
            self._lock, self._own_lock = DirLock(self.directory), True
        try:
            if overwrite:
                clear_store(self.directory)
            info_path = self.directory / "run.json"
            if info_path.exists():
                self._check_same_run(_read_run_json(info_path))
                for name, shape, dtype in self._layout():
                    _check_npy(self.directory / name, shape, dtype)
                self.resumed = True
            else:
                self._create()
            self.values = np.lib.format.open_memmap(self.directory / "values.npy", mode="r+")
            self.stderr = np.lib.format.open_memmap(self.directory / "stderr.npy", mode="r+")
            self.done = np.lib.format.open_memmap(self.directory / "done.npy", mode="r+")
            if self.resumed:
                self._reopen_damaged_rows()
        except BaseException:
            self.close()
            raise

    def _layout(self) -> list[tuple[str, tuple[int, ...], np.dtype]]:
        return [("values.npy", self.shape, np.dtype(np.float64)), ("stderr.npy", self.shape, np.dtype(np.float64)),
                ("done.npy", (self.shape[0],), np.dtype(np.bool_))]

    def _check_same_run(self, info: dict) -> None:
        if info["key"] == self.key:
            return
        old = {"identity": info.get("identity"), "n_frames": info.get("n_frames"), "columns": info.get("columns")}
        new = {"identity": self.identity, "n_frames": self.shape[0], "columns": self.columns}
        _refuse_different_run(self.directory, old, new)

    def _create(self) -> None:
        """Write fresh arrays (each atomically), then run.json (atomically): run.json commits the store."""
        for name, shape, dtype in self._layout():
            fill = False if dtype == np.bool_ else np.nan
            with atomic_path(self.directory / name) as tmp:
                arr = np.lib.format.open_memmap(tmp, mode="w+", dtype=dtype, shape=shape)
                arr[...] = fill
                arr.flush()
                del arr
        info = {"format": STORE_FORMAT, "version": STORE_VERSION, "key": self.key, "n_frames": self.shape[0],
                "columns": self.columns, "identity": self.identity}
        atomic_write_json(self.directory / "run.json", info, indent=1, sort_keys=True)

    def _reopen_damaged_rows(self) -> None:
        """Mark pending again the rows marked done whose numbers no computation writes (a value that is not a finite
        number [W/m^2], a standard error that is NaN, infinite or negative): the store was changed on disk since.
        They are computed again, with one :class:`StoreWarning` naming them, instead of being taken for results."""
        with np.errstate(invalid="ignore"):
            damaged = np.asarray(self.done) & ~(np.isfinite(self.values) & np.isfinite(self.stderr)
                                                & (np.asarray(self.stderr) >= 0)).all(axis=1)
        if not damaged.any():
            return
        rows = np.flatnonzero(damaged)
        self.done[rows] = False
        self.done.flush()
        shown = ", ".join(str(int(i)) for i in rows[:5]) + (" ..." if rows.size > 5 else "")
        warnings.warn(f"{self.directory}: {rows.size} frame(s) marked done hold numbers no run writes (NaN, infinite "
                      f"or a negative standard error; frames {shown}): the store was changed on disk; they are "
                      "computed again", StoreWarning, stacklevel=3)

    def _check_open(self) -> None:
        if self._lock is not None and self._lock.superseded:
            raise StoreError(f"this result store of {self.directory} was superseded by a newer one opened in the "
                             "same process; write through the newer store")
        if getattr(self, "_closed", False):
            raise StoreError(f"the result store of {self.directory} is closed")

    def pending(self) -> np.ndarray:
        """Indices of frames not computed yet."""
        return np.flatnonzero(~np.asarray(self.done))

    def write(self, indices: Any, values: np.ndarray, stderr: np.ndarray) -> None:
        """Store rows for ``indices`` and flush them to disk (values and stderr before ``done``)."""
        self._check_open()
        self.values[indices] = values
        self.stderr[indices] = stderr
        self.values.flush()
        self.stderr.flush()
        self.done[indices] = True
        self.done.flush()

    @property
    def complete(self) -> bool:
        """True when every row has been written."""
        return bool(np.all(self.done))

    def close(self) -> None:
        """Flush and release the directory lock (idempotent). The arrays stay readable."""
        for name in ("values", "stderr", "done"):
            arr = getattr(self, name, None)
            if isinstance(arr, np.memmap) and not getattr(self, "_closed", False):
                with contextlib.suppress(ValueError, OSError):
                    arr.flush()
        self._closed = True
        if self._lock is not None and self._own_lock:
            self._lock.release()

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _check_covers(lock: DirLock, directory: Path) -> None:
    """Refuse a lock that is not held, or that is on neither ``directory`` nor a folder above it."""
    if not lock.held:
        raise StoreError(f"the lock on {lock.directory} is not held (released or superseded); open the store "
                         "inside the run that holds it")
    real = Path(os.path.realpath(directory))
    if real != Path(lock._real) and Path(lock._real) not in real.parents:
        raise StoreError(f"the lock on {lock.directory} does not cover {directory}; keep the store inside the "
                         "locked directory")


class StoreSink:
    """Per-frame results kept in a directory: the :class:`~mincam_sim.frames.FrameSink` that a run gives a solver.

    It carries the identity of the run it belongs to (built by :class:`mincam_sim.runs.run.Run`); the
    :class:`ResultStore` it opens then resumes a killed run with the same identity or refuses a different one
    (naming what changed) unless ``overwrite``. Response maps
    and other content-addressed intermediates go to ``directory/cache``.

    Parameters
    ----------
    directory : str or Path
        The store's directory (created when opened).
    identity : object
        What determines the run's numbers (:func:`mincam_sim.storage.identity.build_identity`).
    overwrite : bool
        Replace the results of a different run.
    lock : DirLock, optional
        The caller's held lock on ``directory`` or a folder above it (:class:`mincam_sim.runs.run.Run` passes its
        own): the store takes no lock of its own. None: the store locks ``directory`` while it is open.

    Raises
    ------
    StoreError
        ``lock`` is not held or does not cover ``directory``.
    """

    persistent = True

    def __init__(self, directory: str | Path, identity: Any, overwrite: bool = False,
                 lock: DirLock | None = None) -> None:
        self.directory, self.identity = Path(directory), identity
        self.overwrite = bool(overwrite)
        if lock is not None:
            _check_covers(lock, self.directory)
        self.lock = lock
        self.cache = ContentCache(self.directory / "cache")

    def refuse_another_run(self) -> None:
        """Refuse, before anything is traced, a store that holds a different run (unless overwriting); the
        opened :class:`ResultStore` checks the same again with its frame count and columns."""
        info_path = self.directory / "run.json"
        if self.overwrite or self.identity is None or not info_path.exists():
            return
        old = _read_run_json(info_path).get("identity")
        new = canonical(self.identity)
        if run_key(old) != run_key(new):
            _refuse_different_run(self.directory, {"identity": old}, {"identity": new})

    def open(self, n_frames: int, columns: Sequence[str]) -> ResultStore:
        """The :class:`ResultStore` of this sink's run (its pending frames are what is left to do)."""
        if self.identity is None:
            raise StoreError("a store keeps the rows of one identified run: measure through mincam_sim.Run "
                             "(run.measure / run.measure_changes), which builds the run's identity")
        return ResultStore(self.directory, n_frames, columns, self.identity, overwrite=self.overwrite,
                           lock=True if self.lock is None else self.lock)


def clear_store(directory: str | Path, extra: Sequence[str] = ()) -> list[Path]:
    """Delete a run directory's store files (``run.json`` first, so a half-cleared store is never taken for a
    committed one) and the named ``extra`` files; return what was deleted. Other files are left alone."""
    directory = Path(directory)
    return remove_files(directory / name for name in (*STORE_FILES, *extra))


IDENTITY_FORMAT = "mincam_sim.storage.identity"


def check_identity(directory: str | Path, identity: Any, overwrite: bool = False,
                   name: str = "identity.json") -> bool:
    """Record what a directory's outputs are computed from, or check that it is unchanged.

    Parameters
    ----------
    directory : str or Path
        Output directory (created if needed).
    identity : object
        Everything that determines the outputs (anything :func:`~mincam_sim.storage.identity.canonical` accepts).
    overwrite : bool
        Replace a different recorded identity instead of refusing.
    name : str
        File name of the record.

    Returns
    -------
    bool
        True if the same identity was already recorded (outputs there may be reused), False if it was written.

    Raises
    ------
    StaleResultError
        A different identity is recorded (the message names what changed), unless ``overwrite``.
    StoreError
        The record is torn or foreign.
    """
    directory = Path(directory)
    _ensure_directory(directory)
    path = directory / name
    canon = canonical(identity)
    key = run_key(canon)
    if path.exists() and not overwrite:
        where = f"{name} in {directory}"
        try:
            info = json.loads(path.read_bytes().decode("utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise StoreError(f"{where} is torn or unreadable ({err}); {_HINT}") from None
        if not isinstance(info, dict) or info.get("format") != IDENTITY_FORMAT or not isinstance(info.get("key"), str):
            raise StoreError(f"{where} was not written by mincam_sim; {_HINT}")
        if info["key"] == key:
            return True
        changed = diff_identities(info.get("identity"), canon, depth=2)
        raise StaleResultError(
            f"{directory} holds results of a different run (changed: {_summary(changed) or 'its identity key'}); "
            "rerun with --overwrite (overwrite=True) to replace them, or choose another output directory"
        )
    try:
        atomic_write_json(path, {"format": IDENTITY_FORMAT, "version": 1, "key": key, "identity": canon},
                          indent=1, sort_keys=True)
    except OSError as err:
        raise StoreError(f"cannot write {path}: {err.strerror or err}") from None
    return False


def lock_out_dir(directory: str | Path, what: str = "output directory") -> DirLock:
    """Create ``directory`` if needed and lock it for this process (:class:`DirLock`)."""
    directory = Path(directory)
    _ensure_directory(directory)
    return DirLock(directory, what)


def topmost_missing(directory: str | Path) -> Path | None:
    """The topmost folder of ``directory``'s path that does not exist yet (what creating it would make), or None."""
    directory = Path(directory)
    return next((p for p in reversed((directory, *directory.parents)) if not p.exists()), None)


def remove_if_only_lock(directory: Path, top: Path) -> None:
    """Remove ``directory`` and the folders above it up to ``top`` (all made for it) if it holds nothing but its
    lock file: a run stopped or refused before it wrote anything leaves no folder behind. A lock another process
    holds by now, and any folder that holds something, are left alone; nothing here raises."""
    lock = directory / LOCK_NAME
    try:
        if any(entry.name != LOCK_NAME for entry in directory.iterdir()):
            return
        if lock.exists():
            import fcntl

            fd = os.open(lock, os.O_RDWR)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # refused: another run holds the folder now
                lock.unlink()
            finally:
                os.close(fd)
        for folder in (directory, *directory.parents):
            folder.rmdir()  # stops (OSError) at the first folder that holds anything
            if folder == top:
                break
    except (OSError, ImportError):
        return


# ---------------------------------------------------------------------------------------- content cache


class CacheWarning(UserWarning):
    """A cache file was torn or did not match its key; it is ignored and recomputed."""


class StoreWarning(UserWarning):
    """Rows of a resumed run's store hold numbers no run writes (changed on disk); they are computed again."""


_KEY_RE = re.compile(r"^[A-Za-z0-9_-]{8,128}$")
_RESERVED = ("__key__", "__digest__", "__meta__")


@dataclass
class CacheEntry:
    """What :meth:`ContentCache.get` returns: the arrays and the JSON metadata stored with them."""

    key: str
    arrays: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)


def _arrays_digest(arrays: dict[str, np.ndarray]) -> str:
    return fingerprint({name: np.asarray(arrays[name]) for name in sorted(arrays)}, 64)


def default_cache_dir() -> Path:
    """``$MINCAM_CACHE_DIR``, else ``$XDG_CACHE_HOME/mincam_sim``, else ``~/.cache/mincam_sim``."""
    if os.environ.get(ENV_CACHE_DIR):
        return Path(os.environ[ENV_CACHE_DIR])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mincam_sim"


class ContentCache:
    """Content-addressed files ``<directory>/<key>.npz``, written atomically, verified on reading.

    The caller derives ``key`` from everything the content depends on
    (:func:`~mincam_sim.storage.identity.fingerprint`);
    the same key then always means the same content, whatever run or frame set asks for it.

    Parameters
    ----------
    directory : str or Path
        Cache directory (created on the first :meth:`put`).
    """

    def __init__(self, directory: str | Path) -> None:
        self.directory = Path(directory)

    def path(self, key: str) -> Path:
        """File of ``key`` (the key must be 8-128 characters of ``[A-Za-z0-9_-]``)."""
        if not isinstance(key, str) or not _KEY_RE.match(key):
            raise ValueError(f"cache key must be 8-128 characters of [A-Za-z0-9_-], got {key!r}")
        return self.directory / f"{key}.npz"

    def __contains__(self, key: str) -> bool:
        return self.get(key) is not None

    def get(self, key: str) -> CacheEntry | None:
        """The entry stored under ``key``, or None if absent. A torn file, or one whose stored key or digest
        does not match, is ignored (with a :class:`CacheWarning`) and removed, so it is recomputed."""
        path = self.path(key)
        if not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as data:
                stored_key = str(data["__key__"])
                digest = str(data["__digest__"])
                meta = json.loads(str(data["__meta__"]))
                arrays = {name: np.array(data[name]) for name in data.files if name not in _RESERVED}
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, json.JSONDecodeError) as err:
            why = "not an .npz archive" if "pickled" in str(err) else f"{type(err).__name__}: {err}"
            self._discard(path, f"torn or unreadable ({why})")
            return None
        if stored_key != key:
            self._discard(path, f"holds key {stored_key!r}")
            return None
        if _arrays_digest(arrays) != digest:
            self._discard(path, "its arrays do not match their stored digest")
            return None
        return CacheEntry(key, arrays, meta if isinstance(meta, dict) else {"meta": meta})

    def _discard(self, path: Path, why: str) -> None:
        warnings.warn(f"ignoring cache file {path}: {why}; it will be recomputed", CacheWarning, stacklevel=3)
        with contextlib.suppress(OSError):
            path.unlink()

    def put(self, key: str, arrays: dict[str, np.ndarray], meta: dict | None = None) -> Path:
        """Store ``arrays`` (numeric numpy arrays) and JSON-serialisable ``meta`` under ``key`` atomically."""
        path = self.path(key)
        bad = [name for name in arrays if name in _RESERVED or not name.isidentifier()]
        if bad:
            raise ValueError(f"cache array names must be identifiers other than {_RESERVED}, got {bad}")
        arrays = {name: np.asarray(a) for name, a in arrays.items()}
        payload = {**arrays, "__key__": np.array(key), "__digest__": np.array(_arrays_digest(arrays)),
                   "__meta__": np.array(json.dumps(meta or {}, default=json_default, sort_keys=True))}
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            with atomic_open(path, "wb") as fh:
                np.savez(fh, **payload)
        except OSError as err:
            raise StoreError(f"cannot write cache file {path}: {err.strerror or err}") from None
        return path

    def get_or_compute(
        self, key: str, compute: Callable[[], tuple[dict[str, np.ndarray], dict]]
    ) -> tuple[CacheEntry, bool]:
        """The entry under ``key``, computing and storing it (``compute() -> (arrays, meta)``) if absent.
        Returns ``(entry, hit)``."""
        entry = self.get(key)
        if entry is not None:
            return entry, True
        arrays, meta = compute()
        self.put(key, arrays, meta)
        return CacheEntry(key, {k: np.asarray(v) for k, v in arrays.items()}, dict(meta or {})), False


__all__ = [
    "CacheEntry",
    "CacheWarning",
    "ContentCache",
    "DirLock",
    "ResultStore",
    "StoreSink",
    "StoreWarning",
    "check_identity",
    "clear_store",
    "default_cache_dir",
    "lock_out_dir",
    "run_key",
]
