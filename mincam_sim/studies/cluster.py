"""Where a study's points run, and how it stops: the cores this process may use, an embedded dask cluster that
Ctrl-C stops at once, an existing scheduler checked within seconds, and Ctrl-C held while a point is written.

* :func:`check_workers`, :func:`worker_count`: ``--workers`` checked (>= 1, not with ``--scheduler``) and capped
  at the cores this process may use (its CPU affinity), with one warning naming the cap.
* :func:`check_scheduler`: a scheduler address is parsed, connected to and asked who it is within
  :data:`SCHEDULER_TIMEOUT_S`; a malformed address, one nobody answers at, or one that answers but is not a dask
  scheduler is refused in one line. It returns how many workers the scheduler has.
* :func:`watched_interrupts`, :func:`raise_if_interrupted`: SIGINT (Ctrl-C) is remembered as well as raised, so
  that one a library swallowed (an import guard catching ``BaseException``) still stops the study at its next
  point; :func:`held_interrupts`: SIGINT inside the block is raised when the block ends, so a point's values and
  its completion record are written whole.
* :func:`embedded_client` / :func:`scheduler_client`: a ``distributed.Client``. The embedded cluster's worker
  processes start with SIGINT ignored (the terminal sends Ctrl-C to the whole process group): the study itself
  stops them. On an interrupt or an error they are killed at once (not drained), the cluster is closed within
  seconds with dask's shutdown chatter muted, and no process this study started is left behind.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from mincam_sim import interrupts
from mincam_sim.errors import ConfigError

ENV_THREADS = "MINCAM_DRJIT_THREADS"
SCHEDULER_TIMEOUT_S = 5.0
CLOSE_TIMEOUT_S = 3.0


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one, else ``os.cpu_count()``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def check_workers(workers: int | None, scheduler: str | None) -> None:
    """Refuse ``workers`` that is not an integer >= 1, or that is given together with ``scheduler``.

    Raises
    ------
    ConfigError
        Naming the option and the fix.
    """
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ConfigError(f"--workers must be an integer >= 1 (1 = in this process), got {workers!r}")
    if workers is not None and scheduler is not None:
        raise ConfigError(f"--workers {workers} does not apply with --scheduler {scheduler} (the scheduler's cluster "
                          "has its own workers): give one of them")


def worker_count(workers: int | None, scheduler: str | None) -> int:
    """The workers of an embedded cluster: ``workers`` (default min(2, cores)) capped, with one warning, at the
    cores this process may use (:func:`available_cores`); checked first by :func:`check_workers`."""
    check_workers(workers, scheduler)
    cores = available_cores()
    if workers is None:
        return min(2, cores)
    if workers > cores:
        warnings.warn(f"--workers {workers} is more than the {cores} cores this process may use: running {cores} "
                      f"worker{'s' if cores > 1 else ''} (more would only wait for the same cores)", UserWarning,
                      stacklevel=3)
        return cores
    return workers


def _scheduler_fix(address: str) -> str:
    return (f"start the scheduler (`dask scheduler`, or a dask-jobqueue cluster's scheduler_address) and pass "
            f"its address, or drop --scheduler to run on this machine (--workers N); got --scheduler {address}")


async def _identity(address: str, timeout_s: float) -> dict:
    from distributed.comm import connect

    comm = await asyncio.wait_for(connect(address, timeout=timeout_s), timeout_s)
    try:
        await asyncio.wait_for(comm.write({"op": "identity", "reply": True}), timeout_s)
        return await asyncio.wait_for(comm.read(), timeout_s)
    finally:
        comm.abort()


def check_scheduler(address: str, timeout_s: float = SCHEDULER_TIMEOUT_S) -> int:
    """Ask the scheduler at ``address`` who it is, within ``timeout_s``; return its number of workers.

    Raises
    ------
    ConfigError
        A malformed address, no answer within ``timeout_s``, or an answer that is not a dask scheduler's.
    """
    from distributed.comm import parse_address
    from distributed.comm.registry import get_backend

    if not isinstance(address, str) or not address.strip():
        raise ConfigError(f"--scheduler must be an address like tcp://host:8786, got {address!r}")
    try:
        scheme, location = parse_address(address)
        get_backend(scheme)  # a scheme dask knows
        if scheme in ("tcp", "tls") and not location.rpartition(":")[2].isdigit():
            raise ValueError(f"missing port number in address {address!r}")
    except ValueError as err:
        raise ConfigError(f"--scheduler {address} is not a scheduler address ({err}); write it like "
                          "tcp://host:8786") from None
    with ThreadPoolExecutor(1) as pool:  # its own event loop: works where one already runs (a notebook)
        future = pool.submit(asyncio.run, _identity(address, timeout_s))
        try:
            reply = future.result(timeout=timeout_s + 1.0)
        except (OSError, TimeoutError) as err:  # asyncio's and concurrent.futures' timeouts are TimeoutError
            why = "no answer" if isinstance(err, TimeoutError) else _one_line(err)
            raise ConfigError(f"cannot reach a dask scheduler at {address} within {timeout_s:g} s ({why}): "
                              f"{_scheduler_fix(address)}") from None
        except Exception as err:  # noqa: BLE001 - garbage from a server that is not dask's, in whatever form
            raise ConfigError(f"{address} answered, but not as a dask scheduler ({type(err).__name__}): "
                              f"{_scheduler_fix(address)}") from None
    if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
        what = reply.get("type") if isinstance(reply, dict) else type(reply).__name__
        raise ConfigError(f"{address} is a dask {what}, not a scheduler: {_scheduler_fix(address)}")
    return len(reply.get("workers") or {})


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


# SIGINTs received while watched; how many held_interrupts blocks are open; what the first one calls
_sigint: dict = {"count": 0, "holding": 0, "on_interrupt": None}


def _on_sigint(signum, frame) -> None:
    """Count the interrupt (the first calls the watching block's ``on_interrupt``); raise it unless a point is
    being written (then :func:`held_interrupts` raises it)."""
    _sigint["count"] += 1
    interrupts.note()
    if _sigint["count"] == 1 and _sigint["on_interrupt"] is not None:
        _sigint["on_interrupt"]()
    if _sigint["holding"] == 0:
        raise KeyboardInterrupt


def _can_handle() -> bool:
    """SIGINT can be handled here: the main thread, and Python's own handler (or this module's) installed."""
    return (threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) in (signal.default_int_handler, interrupts.recording_handler,
                                                    _on_sigint))


@contextlib.contextmanager
def watched_interrupts(on_interrupt: Callable[[], None] | None = None) -> Iterator[None]:
    """Within the block SIGINT raises ``KeyboardInterrupt`` as usual and is also counted, so that an interrupt
    a library swallowed (an import guard that catches ``BaseException``) still stops the study at the next
    :func:`raise_if_interrupted`; the first one also calls ``on_interrupt``. Nested blocks share the outermost
    one's count and ``on_interrupt``.

    An interrupt that lands in a finalizer (a weak reference's callback, a ``__del__``) cannot be raised from
    there: Python prints it as "Exception ignored in ..." and goes on. Within the block such a
    ``KeyboardInterrupt`` is dropped quietly instead (it is counted, and the study stops at its next check);
    every other unraisable exception is shown as before.

    Under the command line (its counting handler installed), an interrupt it counted before the block
    (:mod:`mincam_sim.interrupts`; one an import guard swallowed while the study's modules were imported) is
    raised as the block starts."""
    if not _can_handle() or signal.getsignal(signal.SIGINT) is _on_sigint:
        yield
        return
    if signal.getsignal(signal.SIGINT) is interrupts.recording_handler and interrupts.arrived():
        raise KeyboardInterrupt
    previous, previous_hook = signal.getsignal(signal.SIGINT), sys.unraisablehook

    def unraisable(info) -> None:
        if not (isinstance(info.exc_value, KeyboardInterrupt) and _sigint["count"]):
            previous_hook(info)

    _sigint.update(count=0, holding=0, on_interrupt=on_interrupt)
    signal.signal(signal.SIGINT, _on_sigint)
    sys.unraisablehook = unraisable
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        sys.unraisablehook = previous_hook
        _sigint["on_interrupt"] = None


def raise_if_interrupted() -> None:
    """Raise ``KeyboardInterrupt`` if SIGINT arrived inside :func:`watched_interrupts` (even if it was
    swallowed where it landed)."""
    if _sigint["count"] and _sigint["holding"] == 0 and signal.getsignal(signal.SIGINT) is _on_sigint:
        raise KeyboardInterrupt


@contextlib.contextmanager
def held_interrupts() -> Iterator[None]:
    """Hold SIGINT inside the block (a point's values and its completion record are written whole) and raise
    it (``KeyboardInterrupt``) when the block ends. A plain block outside the main thread."""
    if not _can_handle():
        yield
        return
    with watched_interrupts():
        before = _sigint["count"]
        _sigint["holding"] += 1
        try:
            yield
        finally:
            _sigint["holding"] -= 1
        if _sigint["count"] > before:
            raise KeyboardInterrupt


def _prepare_worker(cache_root: str, dask_worker=None) -> str:
    """In a worker process: ignore Ctrl-C (the study stops its workers), mute the notices of cancelled tasks, and
    give it its own Dr.Jit kernel cache (before Dr.Jit is first imported there). Runs in the worker's main
    thread."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    # its warnings about tasks cancelled when a study stops say nothing to the user
    logging.getLogger("distributed.worker.state_machine").setLevel(logging.ERROR)
    name = "".join(c if c.isalnum() else "_" for c in str(getattr(dask_worker, "name", os.getpid())))
    path = Path(cache_root) / f"worker_{name}"
    path.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("DRJIT_CACHE_DIR", str(path))
    return str(path)


def _dask_loggers() -> list[str]:
    return ["distributed", *[n for n in logging.root.manager.loggerDict if n.startswith("distributed.")]]


def mute_dask_for_exit() -> None:
    """dask's and asyncio's loggers at CRITICAL for the rest of the process: for a command that ends when its
    study stops, whatever they say after a Ctrl-C is about work stopped on purpose (a connection closed, a
    nanny's start task "never retrieved") and came out as tracebacks under the one-line error."""
    for name in ["asyncio", *_dask_loggers()]:
        logging.getLogger(name).setLevel(logging.CRITICAL)


@contextlib.contextmanager
def _muted_dask() -> Iterator[None]:
    """dask's loggers at CRITICAL (its warnings about workers killed on purpose say nothing to the user)."""
    names = _dask_loggers()
    levels = {n: logging.getLogger(n).level for n in names}
    for n in names:
        logging.getLogger(n).setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for n, level in levels.items():
            logging.getLogger(n).setLevel(level)


def _children_since(before: set[int]) -> list:
    return [p for p in multiprocessing.active_children() if p.pid not in before]


def _kill_children(before: set[int]) -> None:
    """Kill (SIGKILL) and reap the processes this process started since ``before`` was taken."""
    children = _children_since(before)
    for proc in children:
        with contextlib.suppress(OSError, ValueError):
            proc.kill()
    for proc in children:
        with contextlib.suppress(OSError, ValueError, AssertionError):
            proc.join(timeout=CLOSE_TIMEOUT_S)


def _close_all(*closing) -> None:
    for item in closing:
        if item is not None:
            with contextlib.suppress(Exception):
                item.close(timeout=CLOSE_TIMEOUT_S)


def _stop_at_once(client, cluster, before: set[int]) -> None:
    """Stop an embedded cluster now: its nannies told not to restart their workers, the worker processes killed
    (not drained: a busy worker would keep computing, and would log the scheduler going away), then the
    cluster and the client closed, and whatever is still alive after a few seconds killed."""
    for nanny in getattr(cluster, "workers", {}).values() if cluster is not None else ():
        with contextlib.suppress(Exception):
            nanny.close_gracefully(reason="study stopped")  # dask's "do not restart": the nanny closes after it
    _kill_children(before)
    closer = threading.Thread(target=_close_all, args=(cluster, client), daemon=True)
    closer.start()
    closer.join(2 * CLOSE_TIMEOUT_S)
    _kill_children(before)  # a worker a nanny started meanwhile


@contextlib.contextmanager
def _spawned_ignoring_sigint(log_path: Path | None = None) -> Iterator[None]:
    """Processes spawned in the block start with SIGINT ignored, so that a Ctrl-C while the workers start
    reaches only this process (a worker importing its modules would print a traceback), and, given
    ``log_path``, with their stderr appended to that file: dask's worker log, a worker's warnings, and what a
    worker started just as the study stops says about its lost parent go there, not under the study's own lines.
    The interpreter is started through a shell script, ``trap '' INT; exec python "$@" 2>>LOG`` (an ignored
    signal stays ignored across ``exec``, and Python then leaves it so); where the script cannot run (no
    ``/bin/sh``, a ``noexec`` temporary folder, a log that cannot be opened) the plain interpreter is used. The
    script lives until the block ends: hold the block until no process can be spawned any more (a nanny
    restarting its worker while the study stops)."""
    import multiprocessing.spawn as mp_spawn

    previous = mp_spawn.get_executable()
    with tempfile.TemporaryDirectory(prefix="mincam_study_") as folder:
        script = Path(folder) / "python_ignoring_sigint"
        redirect = f" 2>>{shlex.quote(os.fsdecode(log_path))}" if log_path is not None else ""
        try:
            script.write_text(f"#!/bin/sh\ntrap '' INT\nexec {shlex.quote(os.fsdecode(previous))} \"$@\"{redirect}\n")
            script.chmod(0o755)
            subprocess.run([str(script), "-c", "pass"], check=True, timeout=60, capture_output=True)
        except (OSError, subprocess.SubprocessError):
            yield
            return
        multiprocessing.set_executable(str(script))
        try:
            yield
        finally:
            mp_spawn.set_executable(previous)


def _quiet_resource_tracker() -> None:
    """Start multiprocessing's resource tracker (if it is not running yet) with its shutdown notice about leaked
    semaphores muted: a study stopped by Ctrl-C kills its workers on purpose, and the tracker, which removes what
    they leave, printed "There appear to be N leaked semaphore objects" under the one-line error. The tracker
    takes its warning filters from ``sys.warnoptions`` when it is started."""
    from multiprocessing import resource_tracker

    if getattr(resource_tracker._resource_tracker, "_pid", None) is not None:
        return
    previous = list(sys.warnoptions)
    sys.warnoptions.append("ignore:resource_tracker:UserWarning")
    try:
        resource_tracker.ensure_running()
    finally:
        sys.warnoptions[:] = previous


@contextlib.contextmanager
def embedded_client(n_workers: int, log_path: Path | None = None) -> Iterator:
    """A client of a ``LocalCluster`` of ``n_workers`` spawned process workers (Dr.Jit threads capped so that
    workers x threads <= cores, their stderr appended to ``log_path`` if given); stopped at once on any
    exception.

    Each worker gets its own Dr.Jit kernel cache (``DRJIT_CACHE_DIR``, unless the user set it) in a temporary
    folder, outside the study's output folder, removed when the block ends (after the workers are gone), also on
    an error or a Ctrl-C."""
    import dask
    from distributed import Client, LocalCluster
    from distributed.deploy.spec import SpecCluster

    before = {p.pid for p in multiprocessing.active_children()}
    clusters_before = set(SpecCluster._instances)
    client = cluster = None
    with (tempfile.TemporaryDirectory(prefix="mincam_drjit_cache_", ignore_cleanup_errors=True) as cache_root,
          _spawned_ignoring_sigint(log_path)):
        try:
            threads = max(1, available_cores() // n_workers)
            with dask.config.set({"distributed.worker.multiprocessing-method": "spawn",
                                  "distributed.worker.daemon": False}):
                _quiet_resource_tracker()
                cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None, env={ENV_THREADS: str(threads)})
            client = Client(cluster)
            client.run(_prepare_worker, str(cache_root))
            raise_if_interrupted()  # swallowed while the cluster started
            yield client
        except BaseException:
            with held_interrupts(), _muted_dask():  # a second Ctrl-C does not cut the clean-up short
                _stop_at_once(client, cluster, before)
                if cluster is None:  # stopped while it started: its workers are gone, dask's exit hook must not wait
                    for half_built in [c for c in list(SpecCluster._instances) if c not in clusters_before]:
                        SpecCluster._instances.discard(half_built)
            raise
        else:
            client.close()
            cluster.close()
        finally:
            _drop_if_empty(log_path)


def _drop_if_empty(path: Path | None) -> None:
    """Remove the workers' log if they wrote nothing to it (the shell creates it when it starts one)."""
    with contextlib.suppress(OSError):
        if path is not None and path.stat().st_size == 0:
            path.unlink()


@contextlib.contextmanager
def scheduler_client(address: str) -> Iterator:
    """A client of the existing scheduler at ``address`` (check it first with :func:`check_scheduler`)."""
    from distributed import Client

    client = Client(address, timeout=SCHEDULER_TIMEOUT_S)
    try:
        yield client
    except BaseException:
        with held_interrupts(), _muted_dask(), contextlib.suppress(Exception):
            client.close(timeout=CLOSE_TIMEOUT_S)
        raise
    client.close()
