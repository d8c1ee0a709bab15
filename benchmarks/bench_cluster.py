"""What running the runs as Ray tasks costs against ``--jobs`` worker processes, per run.

Both engines run ``N`` jobs on two workers: each job sleeps ``WORK_S`` (a stand-in for a run
that does not compete for the cores, so the figures hold on a busy machine) and returns what a
randomized run returns, a record and ``--record`` bytes (``RECORD_BYTES``). Printed per engine:

* start-up: from the call to the first result, less one job's work (a Ray instance of this
  machine started, or the process pool; the workers' first imports of this package);
* per run: the rest of the wall time past the ideal ``N · WORK_S / 2``, per run.
"""

import os
import time
from functools import partial

from wmm_control.experiments.cluster import ray_session, run_tasks
from wmm_control.experiments.jobs import run_jobs

N = 200
WORK_S = 0.05
WORKERS = 2
#: A robot A run's record is about 0.7 kB of JSON; its --record npz about 40 kB.
RECORD_BYTES = 40_000


def job(i, size):
    import wmm_control.experiments.randomized  # noqa: F401  (a run's worker imports it)

    time.sleep(WORK_S)
    return {'goal': i, 'outcome': 'converged'}, {f'{i}.npz': os.urandom(size)}


def _lost(job, why):
    raise RuntimeError(why)


def timed(results):
    start = time.perf_counter()
    first = None
    count = 0
    for _ in results:
        count += 1
        if first is None:
            first = time.perf_counter() - start
    assert count == N
    total = time.perf_counter() - start
    startup = first - WORK_S
    per_run = (total - first - (N - 1) * WORK_S / WORKERS) / (N - 1)
    return startup, per_run


def main():
    fn = partial(job, size=RECORD_BYTES)
    print(f'{N} jobs of {WORK_S * 1e3:.0f} ms, {RECORD_BYTES / 1e3:.0f} kB each, on {WORKERS} workers')
    startup, per_run = timed(run_jobs(fn, range(N), WORKERS))
    print(f'--jobs {WORKERS} (processes):      start-up {startup:6.2f} s, per run {per_run * 1e3:6.1f} ms')
    t0 = time.perf_counter()
    with ray_session('ray', WORKERS) as ray:
        init = time.perf_counter() - t0
        startup, per_run = timed(run_tasks(ray, fn, list(range(N)), _lost))
    print(
        f'--cluster ray (local Ray):  start-up {init + startup:6.2f} s ({init:.2f} s of it ray.init), '
        f'per run {per_run * 1e3:6.1f} ms'
    )


if __name__ == '__main__':
    main()
