"""Parameter sweeps and Monte-Carlo studies on Dask: local by default, a cluster by address.

A study is a list of small, picklable *tasks* (dicts or tuples) and one top-level function
``fn(task)``. :func:`run_tasks` runs ``fn`` on every task and returns the results in task
order. Reproducibility is the caller's contract, and it is easy to keep: every task
carries its own seed (an int, or the entropy of a ``numpy.random.SeedSequence``), from
which ``fn`` derives all of its randomness, e.g.
``np.random.default_rng(np.random.SeedSequence([seed, *task_key]))``. Nothing may depend
on the worker that runs the task, so the same seed gives the same numbers on 1 worker,
8 workers or a remote cluster. :func:`task_seed` builds such a sequence.

Schedulers:

``None`` (default)
    A ``distributed.LocalCluster`` on this machine: ``n_workers`` processes (default
    ``os.cpu_count()``) with one thread each, started for the call and shut down after. Its
    processes write nothing to stderr (a task's exception comes back through the results), so
    a Ctrl-C in the terminal ends the study with one line, not a traceback per worker.
``"serial"``
    A plain loop in this process (for debugging and tiny runs; same numbers).
``"tcp://HOST:PORT"`` (any Dask address)
    A ``distributed.Client`` connected to a running scheduler; its workers need posekit
    installed. An address that cannot be reached within ``connect_timeout_s`` is a
    :class:`~posekit.errors.ConfigError`.
a ``distributed.Client``
    Used as is and left open (tests share one cluster this way).

Batch the work so one task takes at least tens of milliseconds (e.g. one gauge × all its
poses): Dask's per-task overhead is about a millisecond. Compiled (numba ``cache=True``)
kernels are compiled once and loaded from the cache by every worker process.

A script that starts a local cluster must guard its entry point with
``if __name__ == "__main__":`` (workers are spawned processes that import the main module).
"""

import contextlib
import logging
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ._extras import require
from .errors import ConfigError

__all__ = ["run_tasks", "task_seed", "SERIAL", "DEFAULT_CONNECT_TIMEOUT_S"]

#: Scheduler name that runs the tasks in this process.
SERIAL = "serial"
#: Seconds to wait for a remote scheduler before giving up.
DEFAULT_CONNECT_TIMEOUT_S = 5.0
#: Seconds a local cluster may take to close (its workers are killed after that).
_CLOSE_TIMEOUT_S = 10.0


def _distributed(desc: str = ""):
    """``distributed``, or a one-line error naming the ``studies`` extra (and the serial way out)."""
    return require("distributed", "studies", f"{desc or 'a parallel run'} on Dask",
                   alternative=f"run it in this process with --scheduler {SERIAL}")


def task_seed(seed: int, *key: int) -> np.random.SeedSequence:
    """The seed sequence of one task: ``SeedSequence([seed, *key])``.

    Parameters
    ----------
    seed : int
        The study's seed, >= 0.
    *key : int
        Integers >= 0 that identify the task within the study (e.g. corner count and
        gauge index); the same key gives the same sequence whatever else the study holds.

    Returns
    -------
    numpy.random.SeedSequence
    """
    entropy = [int(seed), *(int(k) for k in key)]
    if any(v < 0 for v in entropy):
        raise ConfigError(f"task seed: expected integers >= 0, got {entropy}")
    return np.random.SeedSequence(entropy)


def _want_progress(progress: bool | None) -> bool:
    if progress is None:
        return sys.stderr.isatty()
    return bool(progress)


def _bar(total: int, desc: str, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm
    return tqdm(total=total, desc=desc or None, unit="task", leave=False, file=sys.stderr)


def _run_serial(fn, tasks, bar) -> list:
    out = []
    for task in tasks:
        out.append(fn(task))
        if bar is not None:
            bar.update(1)
    return out


def _gather_in_order(client, fn, tasks, bar) -> list:
    """Submit every task, collect results as they finish, return them in task order."""
    as_completed = _distributed().as_completed

    futures = client.map(fn, list(tasks), pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    results: list[Any] = [None] * len(futures)
    try:
        for fut in as_completed(futures, loop=client.loop):
            results[index[fut.key]] = fut.result()       # re-raises a task's exception here
            fut.release()
            if bar is not None:
                bar.update(1)
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
    return results


def _connect(address: str, timeout_s: float):
    Client = _distributed().Client
    try:
        return Client(address, timeout=timeout_s, set_as_default=False)
    except Exception as exc:  # noqa: BLE001 -- OSError/TimeoutError, but a non-Dask peer can raise anything
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"cannot reach Dask scheduler {address}: {reason}") from None


@contextlib.contextmanager
def _quiet_stderr():
    """File descriptor 2 on /dev/null for the block: the local cluster's worker processes, spawned
    here, inherit it for life, so a Ctrl-C in the terminal (which reaches every process of the
    group) or a worker's own start-up noise prints nothing; errors come back through the results.
    Also used around the cluster's shutdown, whose log lines after an interrupt are no use."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):          # no stderr at all: nothing to keep quiet
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    try:
        yield
    finally:
        try:
            sys.stderr.flush()
        except (OSError, ValueError):
            pass
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def _local_cluster(n_workers: int):
    distributed = _distributed()
    Client, LocalCluster = distributed.Client, distributed.LocalCluster
    SpecCluster = distributed.SpecCluster
    before = set(SpecCluster._instances)
    with _quiet_stderr():
        try:
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.CRITICAL)
        except BaseException:       # e.g. Ctrl-C while the workers start: close the half-built one here
            # (its failed start-up tasks would be logged by asyncio when collected, after our one line)
            logging.getLogger("asyncio").setLevel(logging.CRITICAL)
            for half in set(SpecCluster._instances) - before:
                try:
                    half.close(timeout=_CLOSE_TIMEOUT_S)
                except Exception:   # noqa: BLE001 -- already failing; the first exception is the one to report
                    pass
            raise
        try:
            client = Client(cluster, set_as_default=False)
        except BaseException:
            cluster.close()
            raise
    return cluster, client


def run_tasks(fn: Callable[[Any], Any], tasks: Sequence, *, scheduler=None, n_workers: int | None = None,
              progress: bool | None = None, desc: str = "",
              connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S) -> list:
    """Run ``fn`` on every task, in parallel, and return the results in task order.

    Parameters
    ----------
    fn : callable
        A top-level (importable, picklable) function of one task. It must take all of its
        randomness from the task (see the module docstring).
    tasks : sequence
        Small picklable task descriptions (dicts or tuples with their own seed).
    scheduler : None, 'serial', str or distributed.Client
        None: a local cluster for this call; 'serial': in this process; an address such
        as ``tcp://host:8786``: an existing Dask scheduler; a Client: used and left open.
    n_workers : int, optional
        Worker processes of the local cluster (default ``os.cpu_count()``); only with
        ``scheduler=None``.
    progress : bool, optional
        Show a progress bar on stderr; default: only when stderr is a terminal.
    desc : str
        Label of the progress bar.
    connect_timeout_s : float
        How long to try to reach a remote scheduler, s.

    Returns
    -------
    list
        ``[fn(task) for task in tasks]``, whichever worker ran each.

    Raises
    ------
    ConfigError
        For an unknown scheduler, ``n_workers`` < 1 or with a scheduler other than the
        local one, or a scheduler address that cannot be reached.
    MissingExtraError
        A scheduler other than 'serial' without Dask installed (the ``studies`` extra).
    Exception
        The first exception raised by ``fn`` (the remaining tasks are cancelled).
    """
    tasks = list(tasks)
    if n_workers is not None:
        if scheduler is not None:
            raise ConfigError(f"n_workers applies to the local cluster only, not to scheduler {scheduler!r}")
        if int(n_workers) < 1:
            raise ConfigError(f"n_workers must be >= 1, got {n_workers}")
    if isinstance(scheduler, str) and scheduler != SERIAL and "://" not in scheduler:
        raise ConfigError(f"scheduler: expected '{SERIAL}' or a Dask address like tcp://HOST:PORT, "
                          f"got '{scheduler}'")
    if isinstance(scheduler, str | None) and scheduler != SERIAL:
        _distributed(desc)      # before any work or progress bar: say which extra is missing
    if not tasks:
        return []
    bar = _bar(len(tasks), desc, _want_progress(progress))
    try:
        if scheduler == SERIAL:
            return _run_serial(fn, tasks, bar)
        if scheduler is None:
            workers = int(n_workers) if n_workers is not None else (os.cpu_count() or 1)
            cluster, client = _local_cluster(min(workers, len(tasks)))
            try:
                return _gather_in_order(client, fn, tasks, bar)
            finally:
                with _quiet_stderr():
                    client.close(timeout=_CLOSE_TIMEOUT_S)
                    cluster.close(timeout=_CLOSE_TIMEOUT_S)
        if isinstance(scheduler, str):
            client = _connect(scheduler, connect_timeout_s)
            try:
                return _gather_in_order(client, fn, tasks, bar)
            finally:
                client.close()
        if hasattr(scheduler, "map") and hasattr(scheduler, "cancel"):
            return _gather_in_order(scheduler, fn, tasks, bar)
        raise ConfigError(f"scheduler: expected None, '{SERIAL}', an address or a distributed.Client, "
                          f"got {type(scheduler).__name__}")
    finally:
        if bar is not None:
            bar.close()
