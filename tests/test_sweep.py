"""posekit.sweep: same seed, same numbers on any number of workers; order; clean errors."""

import logging
import sys
import time

import cloudpickle
import numpy as np
import pytest

from posekit.errors import ConfigError, GaugeError
from posekit.profiler.studies.study import CornersConfig, corners_study
from posekit.sweep import SERIAL, run_tasks, task_seed

# Task functions defined here travel to the workers by value (tests/ is not installed).
cloudpickle.register_pickle_by_value(sys.modules[__name__])


def monte_carlo(task):
    """A tiny Monte-Carlo task: its numbers depend on (seed, k) only."""
    seed, k = task
    rng = np.random.default_rng(task_seed(seed, k))
    return rng.normal(size=4).tolist()


def slow_echo(task):
    """Early tasks finish last, so completion order differs from task order."""
    k, total = task
    time.sleep(0.02 * (total - k))
    return k


def fail_on_three(k):
    if k == 3:
        raise GaugeError(f"task {k}: bad gauge")
    return k


@pytest.fixture(scope="module")
def cluster2():
    from distributed import LocalCluster
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR)
    yield cluster.scheduler_address
    cluster.close()


def _corners_arrays(study):
    return [study.samples[n][key] for n in sorted(study.samples) for key in ("status", "reproj_um", "err")]


TINY = CornersConfig(corners=(4, 5), gauges=(2, 3), poses=4, seed=11)


def test_same_seed_same_numbers_on_one_and_two_workers(cluster2):
    tasks = [(7, k) for k in range(6)]
    on_two = run_tasks(monte_carlo, tasks, scheduler=cluster2)
    on_one = run_tasks(monte_carlo, tasks, n_workers=1)
    in_process = run_tasks(monte_carlo, tasks, scheduler=SERIAL)
    assert on_two == on_one == in_process
    assert len({tuple(r) for r in on_two}) == 6                       # every task has its own stream
    assert run_tasks(monte_carlo, [(8, k) for k in range(6)], scheduler=SERIAL) != on_two


def test_tiny_study_identical_across_worker_counts_and_runs(cluster2):
    a = corners_study(TINY, scheduler=cluster2)
    b = corners_study(TINY, scheduler=cluster2)                      # second run, same seed
    c = corners_study(TINY, scheduler=SERIAL)                        # one process
    for x, y, z in zip(_corners_arrays(a), _corners_arrays(b), _corners_arrays(c), strict=True):
        np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(x, z)
    np.testing.assert_equal(a.table, b.table)                       # NaN == NaN here
    d = corners_study(CornersConfig(corners=(4, 5), gauges=(2, 3), poses=4, seed=12), scheduler=SERIAL)
    assert not np.allclose(d.samples[5]["reproj_um"], a.samples[5]["reproj_um"], equal_nan=True)


def test_results_come_back_in_task_order(cluster2):
    tasks = [(k, 12) for k in range(12)]
    assert run_tasks(slow_echo, tasks, scheduler=cluster2) == list(range(12))


def test_task_error_reaches_the_caller(cluster2):
    with pytest.raises(GaugeError, match="task 3: bad gauge"):
        run_tasks(fail_on_three, range(6), scheduler=cluster2)
    with pytest.raises(GaugeError, match="task 3: bad gauge"):
        run_tasks(fail_on_three, range(6), scheduler=SERIAL)


def test_unreachable_scheduler_is_a_quick_config_error():
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match=r"^cannot reach Dask scheduler tcp://127\.0\.0\.1:9: "):
        run_tasks(monte_carlo, [(0, 0)], scheduler="tcp://127.0.0.1:9", connect_timeout_s=1.0)
    assert time.perf_counter() - t0 < 10.0


def test_bad_scheduler_arguments():
    with pytest.raises(ConfigError, match="expected 'serial' or a Dask address like tcp://HOST:PORT, got 'fast'"):
        run_tasks(monte_carlo, [(0, 0)], scheduler="fast")
    with pytest.raises(ConfigError, match="n_workers applies to the local cluster only"):
        run_tasks(monte_carlo, [(0, 0)], scheduler=SERIAL, n_workers=2)
    with pytest.raises(ConfigError, match="n_workers must be >= 1, got 0"):
        run_tasks(monte_carlo, [(0, 0)], n_workers=0)
    with pytest.raises(ConfigError, match="expected None, 'serial', an address or a distributed.Client, got int"):
        run_tasks(monte_carlo, [(0, 0)], scheduler=3)
    assert run_tasks(monte_carlo, [], n_workers=2) == []              # no cluster for no work


def test_task_seed():
    a = np.random.default_rng(task_seed(1, 5, 2)).random(3)
    np.testing.assert_array_equal(a, np.random.default_rng(task_seed(1, 5, 2)).random(3))
    assert not np.array_equal(a, np.random.default_rng(task_seed(1, 2, 5)).random(3))
    with pytest.raises(ConfigError, match=r"expected integers >= 0, got \[-1, 2\]"):
        task_seed(-1, 2)
