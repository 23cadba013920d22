"""The process's worker threads, started once and kept.

One per core, for compiled kernels and numpy calls that release the GIL (the solver's chunks,
the quantization search's parts).

Starting threads for every call costs milliseconds on a busy machine, as much as a small
solve. The pools are made on first use; a process forked from one that had them (a sweep's
pool workers) gets new ones, not the parent's, whose threads do not exist in the child.
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from typing import Any, TypeVar

T = TypeVar("T")
F = TypeVar("F", bound=Callable[..., Any])

# Threads of the shared pool: one per core, at most 4 (the kernels are compute-bound).
THREADS = min(4, os.cpu_count() or 1)
# The shared pool's name: `run_parts` runs its parts there.
SHARED = "rts-worker"

_LOCK = threading.Lock()
_pools: dict[str, ThreadPoolExecutor] = {}
_sizes: dict[str, int] = {}
_local = threading.local()  # .worker: this thread is one of the shared pool's


def _mark_worker() -> None:
    _local.worker = True


def pool(name: str = SHARED, threads: int | None = None) -> ThreadPoolExecutor:
    """Return the process's pool called ``name``, made on first use.

    ``threads``: its size when it is made (default `THREADS`); given for a pool that exists,
    it must be the pool's size.

    Raises
    ------
    ValueError
        ``threads`` is given and the pool exists with another number of threads (a pool of one
        thread keeps its tasks in order; its users rely on that).
    """
    found = _pools.get(name)
    if found is None:
        with _LOCK:
            found = _pools.get(name)
            if found is None:
                size = THREADS if threads is None else threads
                _sizes[name] = size  # first: a pool is seen only with its size known
                found = _pools[name] = ThreadPoolExecutor(
                    size, thread_name_prefix=name,
                    initializer=_mark_worker if name == SHARED else None)
    if threads is not None and _sizes[name] != threads:
        raise ValueError(f"threads: pool {name!r} has {_sizes[name]} thread(s), "
                         f"asked for {threads}")
    return found


def run_parts(fn: Callable[[T], object], parts: Iterable[T]) -> None:
    """Call ``fn`` on every part, on the shared pool's threads when there are several.

    Called from one of those threads (``fn`` running parts of its own), the parts run on it,
    one after another: waiting for the pool from inside it could wait for ever.

    When a part raises, the parts not started yet are not started, the running ones finish,
    and then the exception of the first failing part (in the order given) is raised: no part
    still writes into the caller's arrays once the caller hears of the error.
    """
    start_parts(fn, parts)()


def start_parts(fn: Callable[[T], object], parts: Iterable[T]) -> Callable[[], None]:
    """Start `run_parts` and return the function that waits for it (and raises its error).

    The caller works on meanwhile (the parts run on the pool's threads); it must call the
    returned function before it uses what the parts write. Where `run_parts` would run the
    parts on the calling thread they have run when this returns.
    """
    parts = list(parts)
    if not (len(parts) > 1 and THREADS > 1 and not getattr(_local, "worker", False)):
        for part in parts:
            fn(part)
        return _nothing
    futures = [pool().submit(fn, part) for part in parts]

    def finish() -> None:
        _, pending = wait(futures, return_when=FIRST_EXCEPTION)
        if pending:  # a part failed
            for future in pending:
                future.cancel()
            wait(pending)
        for future in futures:
            if not future.cancelled() and (error := future.exception()) is not None:
                raise error

    return finish


def _nothing() -> None:
    pass


_controllers: dict[int, Any] = {}


def _controller() -> Any:
    """Return the BLAS libraries loaded now (`threadpoolctl`; about 1 ms to find).

    Found again when modules were imported since (a module may bring its own BLAS, as scipy
    does), else reused.
    """
    key = len(sys.modules)
    found = _controllers.get(key)
    if found is None:
        from threadpoolctl import ThreadpoolController  # loaded on first use: ~10 ms

        _controllers.clear()
        found = _controllers[key] = ThreadpoolController()
    return found


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the body with BLAS on one thread (`threadpoolctl`), when called on the main thread.

    The matrices here are small: more BLAS threads do not help them, and after each call they
    keep spinning for a while, taking the cores from the worker threads (a quarter to a half
    of a compiled kernel's time on two cores, measured). The limit is the process's, and only
    the main thread can set it reliably: OpenBLAS ignores a limit set from another thread once
    the main thread has set one, and bodies overlapping on other threads would restore each
    other's limits, leaving BLAS on one thread for good. So on any thread but the main one the
    body runs as it is: a program that solves from other threads and wants the cores for the
    solver's own threads limits BLAS itself (``threadpoolctl.threadpool_limits(1, "blas")``
    on its main thread, or ``OPENBLAS_NUM_THREADS=1``). Nested bodies restore the limits they
    found.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    with _controller().limit(limits=1, user_api="blas"):
        yield


def with_one_blas_thread(fn: F) -> F:
    """Decorate ``fn`` to run in `one_blas_thread`."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with one_blas_thread():
            return fn(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def _forget_pools() -> None:
    # In a forked child the parent's threads are gone: pools start afresh when first used, and
    # the thread that forked (maybe one of the pool's) is no pool thread there.
    global _LOCK, _local
    _LOCK = threading.Lock()
    _pools.clear()
    _sizes.clear()
    _local = threading.local()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pools)


__all__ = ["SHARED", "THREADS", "one_blas_thread", "pool", "run_parts", "start_parts",
           "with_one_blas_thread"]
