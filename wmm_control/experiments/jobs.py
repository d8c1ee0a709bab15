"""Independent runs in worker processes, their results in a fixed order.

``wmm_experiment --jobs`` and ``wmm_randomized --jobs`` hand their runs to :func:`run_jobs`:
each run is deterministic given its inputs, so the results are those of running them one
after the other in this process, whatever the number of workers.
"""

import argparse
import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any

__all__ = ['run_jobs', 'default_jobs', 'jobs_argument']


def default_jobs() -> int:
    """Worker processes by default: one per core."""
    return os.cpu_count() or 1


def jobs_argument(text: str) -> int:
    """The ``--jobs`` argument (an ``argparse`` type): a positive integer."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f'expected a positive whole number of worker processes, got {text!r}')
    return value


def run_jobs(fn: Callable[[Any], Any], jobs: Iterable[Any], workers: int) -> Iterator[Any]:
    """Yield ``fn(job)`` for every job of ``jobs``, in their order.

    With ``workers`` 1 (or a single job) each runs in this process when its result is asked
    for; otherwise all of them are handed at once to ``workers`` separate processes (at most one
    per job) and their results come back in the order of ``jobs``. ``fn`` and the jobs must be
    picklable: a module-level function (or a ``functools.partial`` of one) and plain data.

    The workers are started afresh (``forkserver``), not forked from this process: a process
    that has run ROS nodes keeps middleware threads whose locks a forked child could inherit
    held, and hang.
    """
    jobs = list(jobs)
    if workers == 1 or len(jobs) <= 1:
        for job in jobs:
            yield fn(job)
        return
    with ProcessPoolExecutor(
        max_workers=min(workers, len(jobs)), mp_context=multiprocessing.get_context('forkserver')
    ) as pool:
        yield from pool.map(fn, jobs)
