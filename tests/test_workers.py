"""The shared worker threads: every part runs, errors come back, a forked child gets its own."""

import multiprocessing
import os
import threading

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from rts_scenario import workers


def test_every_part_runs_once_on_the_pool():
    seen = []
    lock = threading.Lock()

    def note(part):
        with lock:
            seen.append((part, threading.current_thread().name))

    workers.run_parts(note, range(50))
    assert sorted(p for p, _ in seen) == list(range(50))
    if workers.THREADS > 1:
        assert all(name.startswith("rts-worker") for _, name in seen)


def test_an_error_in_a_part_reaches_the_caller():
    def fail(part):
        if part == 3:
            raise ValueError("part 3")

    with pytest.raises(ValueError, match="part 3"):
        workers.run_parts(fail, range(6))


def test_the_pool_is_kept_between_calls():
    assert workers.pool() is workers.pool()
    assert workers.pool("other", threads=1) is not workers.pool()


def _child(queue):
    total = []
    workers.run_parts(total.append, range(8))
    queue.put(sorted(total))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork only")
def test_a_forked_child_gets_its_own_threads():
    # The parent's pool has threads; in a forked child they do not exist, so a pool kept
    # across the fork would take the child's parts and never run them.
    workers.run_parts(lambda part: None, range(4))
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_child, args=(queue,))
    child.start()
    child.join(60)
    if child.is_alive():
        child.kill()
        pytest.fail("the forked child's parts never ran")
    assert child.exitcode == 0
    assert queue.get(timeout=5) == list(range(8))


def test_blas_runs_on_one_thread_inside_and_as_before_after():
    np.ones((4, 4)) @ np.ones((4, 4))  # BLAS loaded
    before = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    with workers.one_blas_thread():
        inside = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    after = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    assert inside and all(n == 1 for n in inside)
    assert after == before


def test_blas_limits_from_other_threads_leave_the_process_as_it_was():
    # threadpoolctl lets one thread set the process's BLAS limits: bodies on two other threads
    # overlapping in time (A in, B in, A out, B out) would otherwise leave BLAS on one thread.
    def blas_threads():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    np.ones((4, 4)) @ np.ones((4, 4))
    with workers.one_blas_thread():  # the main thread first, as a run does
        pass
    before = blas_threads()
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()

    def a():
        with workers.one_blas_thread():
            a_in.set()
            b_in.wait(10)
        a_out.set()

    def b():
        a_in.wait(10)
        with workers.one_blas_thread():
            b_in.set()
            a_out.wait(10)

    threads = [threading.Thread(target=a), threading.Thread(target=b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert blas_threads() == before
    with workers.one_blas_thread():  # and the main thread still limits it
        assert all(n == 1 for n in blas_threads())
        with workers.one_blas_thread():
            assert all(n == 1 for n in blas_threads())
        assert all(n == 1 for n in blas_threads())
    assert blas_threads() == before


def test_parts_of_parts_run_without_waiting_for_the_pool():
    # Every pool thread running a part that itself runs parts: waiting for the pool from
    # inside it would wait for ever.
    done = []
    lock = threading.Lock()

    def inner(part):
        with lock:
            done.append(part)

    def outer(part):
        workers.run_parts(inner, [(part, k) for k in range(3)])

    finished = threading.Event()

    def main():
        workers.run_parts(outer, range(2 * workers.THREADS))
        finished.set()

    threading.Thread(target=main, daemon=True).start()
    assert finished.wait(30), "parts of parts never finished"
    assert sorted(done) == [(p, k) for p in range(2 * workers.THREADS) for k in range(3)]
