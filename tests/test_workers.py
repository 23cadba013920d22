"""The shared worker threads: every part runs, errors come back, a forked child gets its own."""

import multiprocessing
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

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


def test_after_an_error_no_part_is_still_running():
    # The caller hears of the error only once the parts already running have finished (they
    # write into the caller's arrays); parts not started are not started.
    running = []
    finished = []
    lock = threading.Lock()

    def part(p):
        with lock:
            running.append(p)
        if p == 0:
            time.sleep(0.05)  # the others start meanwhile
            raise ValueError("part 0")
        time.sleep(0.3)
        with lock:
            finished.append(p)

    with pytest.raises(ValueError, match="part 0"):
        workers.run_parts(part, range(8))
    with lock:
        assert sorted(finished) == sorted(p for p in running if p != 0)
        assert len(running) < 8  # the rest were never started


def test_the_first_failing_part_is_the_one_reported():
    # Part 5 fails first in time, part 1 first in the order given: part 1's error is raised.
    def fail(part):
        if part in (1, 5):
            time.sleep(0.2 if part == 1 else 0.0)
            raise ValueError(f"part {part}")

    with pytest.raises(ValueError, match="part 1"):
        workers.run_parts(fail, range(6))


def test_started_parts_run_while_the_caller_works_on():
    if workers.THREADS < 2:
        pytest.skip("one core: parts run on the calling thread")
    release = threading.Event()
    done = []

    def part(p):
        release.wait(30)
        done.append(p)

    finish = workers.start_parts(part, range(4))
    assert done == []  # the caller is back before any part could finish
    release.set()
    finish()
    assert sorted(done) == [0, 1, 2, 3]


def test_started_parts_report_their_error_when_waited_for():
    def fail(part):
        if part == 2:
            raise ValueError("part 2")

    with pytest.raises(ValueError, match="part 2"):  # when waited for (at once on one core)
        workers.start_parts(fail, range(4))()


def test_the_pool_is_kept_between_calls():
    assert workers.pool() is workers.pool()
    assert workers.pool("other", threads=1) is not workers.pool()


def test_a_pool_is_not_handed_out_with_another_size():
    workers.pool("single", threads=1)
    with pytest.raises(ValueError, match="pool 'single' has 1 thread"):
        workers.pool("single", threads=2)
    assert workers.pool("single") is workers.pool("single", threads=1)  # any size asked: as is


def test_threads_of_other_pools_still_run_parts_on_the_shared_pool():
    names = []
    workers.pool("other", threads=1).submit(
        workers.run_parts, lambda p: names.append(threading.current_thread().name),
        range(4)).result(timeout=30)
    if workers.THREADS > 1:
        assert all(name.startswith(workers.SHARED) for name in names)


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


def _blas_threads():
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def _fork_and_run_parts(queue):
    # Runs on a pool thread: the child it forks has that thread as its main one, and is no
    # pool thread there, so its parts go to a pool of its own.
    ctx = multiprocessing.get_context("fork")
    inner = ctx.Queue()
    child = ctx.Process(target=_child_names, args=(inner,))
    child.start()
    child.join(60)
    if child.is_alive():
        child.kill()
        return None
    return inner.get(timeout=5)


def _child_names(queue):
    main = threading.get_ident()
    idents = []
    workers.run_parts(lambda part: idents.append(threading.get_ident()), range(6))
    queue.put([ident != main for ident in idents])


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork only")
@pytest.mark.skipif(workers.THREADS < 2, reason="one core: parts run inline anyway")
def test_a_child_forked_from_a_pool_thread_uses_a_pool():
    off_main = workers.pool().submit(_fork_and_run_parts, None).result(timeout=90)
    assert off_main is not None, "the forked child's parts never ran"
    assert off_main == [True] * 6  # on the child's pool, not inline on its (forked) thread


def test_blas_runs_on_one_thread_inside_and_as_before_after():
    np.ones((4, 4)) @ np.ones((4, 4))  # BLAS loaded
    with threadpool_limits(limits=2, user_api="blas"):  # more than one thread to begin with
        before = _blas_threads()
        if not any(n > 1 for n in before):
            pytest.skip("BLAS here runs on one thread only: nothing to limit")
        with workers.one_blas_thread():
            inside = _blas_threads()
        after = _blas_threads()
    assert inside and all(n == 1 for n in inside)
    assert after == before


def test_blas_limits_from_other_threads_leave_the_process_as_it_was():
    # threadpoolctl lets one thread set the process's BLAS limits: bodies on two other threads
    # overlapping in time (A in, B in, A out, B out) would otherwise leave BLAS on one thread.
    blas_threads = _blas_threads
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


_PARTS_OF_PARTS = """
import threading
from rts_scenario import workers

done = []
lock = threading.Lock()

def inner(part):
    with lock:
        done.append(part)

def outer(part):
    workers.run_parts(inner, [(part, k) for k in range(3)])

workers.run_parts(outer, range(2 * workers.THREADS))
assert sorted(done) == [(p, k) for p in range(2 * workers.THREADS) for k in range(3)]
print("ok")
"""


def test_parts_of_parts_run_without_waiting_for_the_pool():
    # Every pool thread running a part that itself runs parts: waiting for the pool from
    # inside it would wait for ever. In a process of its own, so that a hang fails this test
    # (the pool's threads, blocked, would keep the test session from exiting).
    try:
        result = subprocess.run([sys.executable, "-c", _PARTS_OF_PARTS], capture_output=True,
                                text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("parts of parts never finished")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "ok"
