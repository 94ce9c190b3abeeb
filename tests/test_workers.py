import gc
import math
import os
import signal
import subprocess
import sys
import time

import equinox._errors
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tid_jax import _launch, _workers
from tid_jax._workers import (
    WORKERS_ENVIRONMENT_VARIABLE,
    process_count,
    run_lanes,
    run_shares,
    start_workers,
)


def _slow_pid(seconds):
    time.sleep(seconds)
    return os.getpid()


def _slow_collector(seconds):
    time.sleep(seconds)
    return os.getpid(), gc.get_threshold()


def _die_outside(pid):
    """Ends the process running it unless it is the process `pid`."""
    if os.getpid() != pid:
        os._exit(3)
    return "done here"


@pytest.fixture
def two_processes(monkeypatch):
    monkeypatch.setenv(WORKERS_ENVIRONMENT_VARIABLE, "2")


def test_lanes_are_shared_with_a_worker_process_and_returned_in_order(two_processes):
    assert process_count(8) == 2
    assert process_count(1) == 1
    # Slow enough that the worker, once started, takes some of them.
    pids = run_lanes(_slow_pid, [(0.5,)] * 12)
    assert len(pids) == 12
    assert os.getpid() in pids
    assert len(set(pids)) == 2
    assert run_lanes(pow, [(2, i) for i in range(9)]) == [2**i for i in range(9)]


def _shifted(values, pairs, offset):
    return values + offset, {"first": pairs[:, 0]}


def test_shares_of_lanes_come_back_in_the_lanes_order(two_processes):
    # Two shares (lanes 0, 2, 4, 6 and 1, 3, 5), each a task; the results of both, every
    # array of them, put back lane by lane.
    values, pairs = np.arange(7.0), np.arange(14.0).reshape(7, 2)
    shifted, info = run_shares(_shifted, (values, pairs), 10.0)
    np.testing.assert_array_equal(shifted, values + 10.0)
    np.testing.assert_array_equal(info["first"], pairs[:, 0])


def _shifted_pid(values, offset):
    return values + offset, np.full(values.shape, os.getpid())


def test_shares_run_here_take_the_shapes_of_the_shares(two_processes):
    # `here`: every share in this process, one call per share of the same lanes as
    # with the workers (what a later call of those shapes finds compiled).
    values = np.arange(7.0)
    shifted, pids = run_shares(_shifted_pid, (values,), 10.0, here=True)
    np.testing.assert_array_equal(shifted, values + 10.0)
    assert set(pids.tolist()) == {os.getpid()}
    shapes = []
    run_shares(lambda v: shapes.append(v.shape) or (v,), (values,), here=True)
    assert shapes == [(4,), (3,)]


def test_an_error_in_a_worker_is_raised_here(two_processes):
    with pytest.raises(ValueError, match="math domain error"):
        run_lanes(math.sqrt, [(4.0,), (9.0,), (-1.0,), (16.0,)])
    # The workers still serve later calls.
    assert run_lanes(math.sqrt, [(4.0,), (9.0,)]) == [2.0, 3.0]


def test_tasks_of_a_worker_that_died_are_done_here(two_processes):
    here = os.getpid()
    assert run_lanes(_die_outside, [(here,)] * 4) == ["done here"] * 4
    # A new worker replaces it.
    assert run_lanes(math.sqrt, [(4.0,), (9.0,)]) == [2.0, 3.0]
    assert all(worker.alive() for worker in _workers._pool)


@pytest.mark.parametrize("value", ["0", "-2", "two", ""])
def test_bad_worker_count_is_refused_with_its_name(monkeypatch, value):
    monkeypatch.setenv(WORKERS_ENVIRONMENT_VARIABLE, value)
    with pytest.raises(ValueError, match=WORKERS_ENVIRONMENT_VARIABLE):
        process_count(4)


def _compiled_pid(seed, seconds):
    """Compiles (or loads) a program of its own for `seed`, runs it, then sleeps
    `seconds`: this process's id and when the program had run."""
    jax.block_until_ready(jax.jit(_scaled, static_argnums=1)(jnp.ones(3), seed))
    ready = time.time()
    time.sleep(seconds)
    return os.getpid(), ready


def _scaled(x, seed):
    return jnp.sin(x * seed) + seed


def _seed():
    return float(time.time_ns() % 10**9)  # a program no process has compiled before


def test_a_worker_waits_to_load_a_program_this_process_compiles(two_processes):
    run_lanes(_compiled_pid, [(_seed(), 0.2)] * 4)  # the worker running, with JAX loaded
    (worker, worker_ready), (here, here_ready) = run_lanes(
        _compiled_pid, [(_seed(), 1.0)] * 2, compiles=True)
    # This process took the last task first and compiled the program; the worker, about
    # to compile it too, waited for that task to end (its second of sleep).
    assert here == os.getpid() != worker
    assert worker_ready >= here_ready + 1.0


def test_a_worker_loads_a_program_found_in_the_cache_at_once(two_processes):
    run_lanes(_compiled_pid, [(_seed(), 0.2)] * 4)
    seed = _seed()
    _compiled_pid(seed, 0.0)  # compiled in this process only, and kept in the cache
    (worker, worker_ready), (here, here_ready) = run_lanes(
        _compiled_pid, [(seed, 2.0)] * 2, compiles=True)
    # The worker found the program in the cache: it did not wait for this process's task.
    assert here == os.getpid() != worker
    assert worker_ready < here_ready + 2.0


def test_without_the_cache_a_worker_compiles_its_own_programs_at_once(two_processes,
                                                                     monkeypatch):
    _workers._stop_workers()
    monkeypatch.setattr(_workers, "cache_folder", lambda: None)  # for the new worker
    try:
        run_lanes(_slow_pid, [(0.2,)] * 4)  # the worker running, with JAX loaded
        # No warm-up either: it would compile for the worker alone.
        assert not start_workers(2, (_slow_pid, (1.0,)))
        # No cache to share programs through: the worker does not wait for this
        # process's first task (the last) but takes one at once and compiles the
        # program itself, so that each process takes one of two tasks (one after the
        # other would take 4 s) and the worker learns the function.
        seed = _seed()
        started = time.time()
        done = run_lanes(_compiled_pid, [(seed, 2.0)] * 2, compiles=True)
        here = os.getpid()
        assert done[-1][0] == here and done[0][0] != here
        assert done[0][1] < done[-1][1] + 2.0
        assert time.time() - started < 3.5
        # Nor at later calls of the same function.
        started = time.time()
        pids = run_lanes(_compiled_pid, [(seed, 2.0)] * 2, compiles=True)
        assert len({pid for pid, _ in pids}) == 2
        assert time.time() - started < 3.5
    finally:
        _workers._stop_workers()  # later tests get a worker with the cache


def test_a_warm_up_compiles_in_a_worker_and_the_next_lanes_wait_for_it(two_processes):
    run_lanes(_compiled_pid, [(_seed(), 0.2)] * 4)
    seed = _seed()
    hits = []

    def listen(event, **kwargs):
        if event == "/jax/compilation_cache/cache_hits":
            hits.append(event)

    jax.monitoring.register_event_listener(listen)
    try:
        started = time.time()
        start_workers(2, (_compiled_pid, (seed, 1.0)))
        # One task: this process alone runs it, once the warm-up (its second of sleep
        # included) has ended, and loads the program the worker compiled and kept.
        [(here, ready)] = run_lanes(_compiled_pid, [(seed, 0.0)], compiles=True)
    finally:
        jax.monitoring.unregister_event_listener(listen)
    assert here == os.getpid()
    assert ready >= started + 1.0
    assert hits


def test_a_warm_up_that_fails_is_dropped(two_processes):
    start_workers(2, (math.sqrt, (-1.0,)))
    assert run_lanes(math.sqrt, [(4.0,), (9.0,)]) == [2.0, 3.0]


def _started_pid(seconds):
    started = time.time()
    time.sleep(seconds)
    return os.getpid(), started


def _mark(path):
    open(path, "w").close()


def test_lanes_of_another_function_start_here_and_the_worker_joins_after_its_warm_up(
        two_processes):
    run_lanes(_slow_pid, [(0.2,)] * 4)  # the worker running
    called = time.time()
    start_workers(2, (_slow_pid, (2.0,)), serves=_compiled_pid)
    done = run_lanes(_started_pid, [(0.5,)] * 8)
    here = os.getpid()
    # This process began at once, without waiting for the warm-up (for another function);
    # the worker took tasks once its warm-up had ended.
    assert min(started for pid, started in done if pid == here) < called + 1.0
    theirs = [started for pid, started in done if pid != here]
    assert theirs and min(theirs) >= called + 2.0


def test_a_warm_up_while_the_worker_warms_up_is_dropped(two_processes, tmp_path):
    # As where a call was interrupted before its lanes, or where a warm-up for a later
    # step is under way: the worker answers one task at a time, so the second warm-up is
    # not sent, and the call goes on at once.
    run_lanes(_slow_pid, [(0.2,)] * 4)
    started = time.perf_counter()
    assert start_workers(2, (_slow_pid, (1.0,)))
    assert not start_workers(2, (_mark, (tmp_path / "second",)))
    assert time.perf_counter() - started < 0.5
    assert run_lanes(math.sqrt, [(4.0,), (9.0,), (16.0,)]) == [2.0, 3.0, 4.0]
    assert not (tmp_path / "second").exists()


def _ended(pid: int) -> bool:
    """Whether the process `pid` has ended (gone, or a zombie not yet reaped)."""
    try:
        with open(f"/proc/{pid}/stat") as file:
            return file.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads /proc (Linux)")
def test_a_worker_ends_when_its_parent_is_killed_in_the_middle_of_a_task():
    # Killed outright, the parent never closes the worker's input: the worker, busy with a
    # task of a minute, notices that its parent has gone and ends within seconds.
    with subprocess.Popen([sys.executable, "-c", (
        "import threading, time\n"
        "from tid_jax import _workers\n"
        "worker = _workers._Worker()\n"
        "threading.Thread(target=worker.run, args=(time.sleep, (60,)), daemon=True).start()\n"
        "print(worker.process.pid, flush=True)\n"
        "time.sleep(60)\n")], stdout=subprocess.PIPE, text=True) as parent:
        pid = int(parent.stdout.readline())
        time.sleep(1.0)
        assert not _ended(pid)
        parent.send_signal(signal.SIGKILL)
    deadline = time.monotonic() + 20
    while not _ended(pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert _ended(pid)


# --- workers started by the command line before it imports JAX (`_launch`) -----------------


@pytest.mark.parametrize(("argv", "environment", "expected"), [
    (["retune"], {}, 1),  # two cores: one worker beside this process
    (["sensitivity", "--amplitudes", "100"], {}, 1),
    (["robust", "--workers", "3"], {}, 2),
    (["robust", "--workers=1"], {}, 0),
    (["identify", "records.csv", "--model", "backlash"], {}, 1),
    (["retune"], {WORKERS_ENVIRONMENT_VARIABLE: "4"}, 3),
    (["retune", "--workers", "2"], {WORKERS_ENVIRONMENT_VARIABLE: "4"}, 1),
    (["retune", "--workers", "two"], {}, 0),  # the command refuses it
    (["frf"], {}, 0),  # no lanes to deal out
    (["retune", "--help"], {}, 0),
    ([], {}, 0),
    (["retune"], {"JAX_PLATFORMS": "cuda"}, 0),
])
def test_the_command_line_starts_the_workers_its_command_uses(monkeypatch, argv, environment,
                                                              expected):
    monkeypatch.delenv(WORKERS_ENVIRONMENT_VARIABLE, raising=False)
    monkeypatch.delenv("JAX_PLATFORMS", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    for name, value in environment.items():
        monkeypatch.setenv(name, value)
    assert _launch.early_workers(argv) == expected


def test_a_worker_started_early_serves_the_lanes(two_processes):
    _workers._stop_workers()
    process = _launch.spawn_worker(x64=jax.config.jax_enable_x64,
                                   on_error=equinox._errors.EQX_ON_ERROR)
    _launch._started.append(process)
    try:
        answers = run_lanes(_slow_collector, [(0.3,)] * 8)
        assert {pid for pid, _ in answers} == {os.getpid(), process.pid}
        assert [worker.process for worker in _workers._pool] == [process]
        # and collects garbage at the command's thresholds
        assert dict(answers)[process.pid] == _launch.GC_THRESHOLDS
    finally:
        _workers._stop_workers()


def test_the_command_collects_garbage_rarely():
    # As its workers do (its subcommand replaced here, one without workers).
    code = ("import gc, sys\nimport tid_jax.cli\nfrom tid_jax import _launch\n"
            "tid_jax.cli.run = lambda: print(gc.get_threshold())\n"
            "sys.argv = ['tid-jax', 'frf']\n_launch.run()")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.stdout.strip() == str(_launch.GC_THRESHOLDS)


def test_a_worker_started_early_and_not_needed_ends_quietly():
    # Started for a command that then fails on its arguments: its input closes unread.
    with subprocess.Popen([sys.executable, "-c", (
        "from tid_jax import _launch\n"
        "worker = _launch.spawn_worker(x64=True, on_error='raise')\n"
        "print(worker.pid, flush=True)\n")], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True) as parent:
        pid = int(parent.stdout.readline())
        assert parent.wait(timeout=30) == 0
        assert parent.stderr.read() == ""
    deadline = time.monotonic() + 60
    while not _ended(pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert _ended(pid)
