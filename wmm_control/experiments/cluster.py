"""Independent runs as Ray tasks, on this machine or a Ray cluster, their results back here.

``wmm_randomized --cluster`` and ``wmm_experiment --cluster`` hand their runs to
:func:`run_tasks` inside :func:`ray_session`. The ``--cluster`` value says where they run
(:func:`cluster_address`):

* ``ray``: a Ray instance of this machine, started for the study (``--jobs`` CPUs; a new one,
  even where a cluster runs) and stopped after it; nothing to set up;
* ``ray:auto``: the cluster this machine is a node of (``ray start --head`` here, or ``ray
  start --address=HEAD:PORT``), found as ``ray`` finds it (``RAY_ADDRESS``, or the one started
  last on this machine);
* ``ray:HOST:PORT``: the cluster whose head ``ray start --head --port PORT`` started on HOST;
* ``ray://HOST:PORT``: the Ray client server of a cluster's head (port 10001 by default), for
  a machine that is not one of its nodes.

Each run is one task of one CPU. Its result, and the files it wrote (:func:`files_of`), come
back to this process through Ray, which writes them: the machines share no disk. A task whose
worker process or node dies is run again elsewhere (Ray's task retries, up to
:data:`MAX_RETRIES` times), so no run is lost nor counted twice; a run that raises is not
retried (its function decides what its error becomes). Ray (PyPI ``ray``, the ``cluster``
extra of ``setup.py``, ``scripts/requirements-cluster.txt``) is imported only here, and only
when a ``--cluster`` is given.
"""

import logging
import os
import socket
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from wmm_control.errors import WmmError

__all__ = [
    'MAX_RETRIES',
    'CLUSTER_HELP',
    'cluster_address',
    'ray_session',
    'run_tasks',
    'in_order',
    'files_of',
    'write_files',
]

#: Times a task is run again after its worker process or node died.
MAX_RETRIES = 3
#: How long a cluster's address may take to accept a connection [s].
CONNECT_TIMEOUT_S = 5.0
#: How often the retries are counted while the runs go on [s].
POLL_S = 1.0
#: The ``--cluster`` help of both command-line tools.
CLUSTER_HELP = (
    'run the runs as Ray tasks: "ray" starts Ray on this machine (--jobs CPUs), "ray:auto" joins '
    'the cluster this machine is a node of, "ray:HOST:PORT" the one whose head listens there, '
    '"ray://HOST:PORT" through its Ray client server (needs pip install .[cluster])'
)


def cluster_address(text: str) -> str | None:
    """The Ray address of a ``--cluster`` value: None for ``ray`` (a Ray instance of this
    machine), ``'auto'`` for ``ray:auto``, ``'HOST:PORT'`` for ``ray:HOST:PORT``, the value
    itself for ``ray://HOST:PORT``.

    Raises:
        WmmError: any other value.
    """
    if text == 'ray':
        return None
    if text == 'ray:auto':
        return 'auto'
    address = text if text.startswith('ray://') else text.removeprefix('ray:') if text.startswith('ray:') else ''
    host, sep, port = address.removeprefix('ray://').rpartition(':')
    if not (host and sep and port.isdigit()):
        raise WmmError(f'--cluster: expected ray, ray:auto, ray:HOST:PORT or ray://HOST:PORT, got {text!r}')
    return address


def _answers(text: str, address: str) -> None:
    """Raise a one-line WmmError unless ``address`` (HOST:PORT, or ray://HOST:PORT) accepts a
    TCP connection within :data:`CONNECT_TIMEOUT_S`."""
    host, _, port = address.removeprefix('ray://').rpartition(':')
    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise WmmError(f'--cluster {text}: nothing answers at {host}:{port} ({exc.strerror or exc})') from None


@contextmanager
def ray_session(text: str, cpus: int) -> Iterator[Any]:
    """Ray, connected as the ``--cluster`` value ``text`` says (``cpus``: the CPUs of a Ray
    instance started here); disconnected (and that instance stopped) on leaving.

    Raises:
        WmmError: Ray not installed, a malformed value, or no cluster answering at the address:
            before any run starts.
    """
    address = cluster_address(text)
    try:
        import ray
    except ImportError:
        raise WmmError(
            f'--cluster {text}: Ray is not installed; pip install ".[cluster]" '
            '(or pip install -r scripts/requirements-cluster.txt)'
        ) from None
    given = os.environ.get('RAY_ADDRESS', '') if address == 'auto' else address  # where ray:auto looks first
    if given and given != 'auto':
        _answers(text, given)
    try:
        if address is None:
            # 'local': a new instance, even where a cluster runs (ray.init would join that one)
            ray.init(
                address='local',
                num_cpus=cpus,
                include_dashboard=False,
                log_to_driver=False,
                logging_level=logging.ERROR,
            )
        else:
            ray.init(address=address, log_to_driver=False, logging_level=logging.ERROR)
    except ConnectionError as exc:
        raise WmmError(f'--cluster {text}: no Ray cluster answers ({str(exc).splitlines()[0]})') from None
    try:
        yield ray
    finally:
        ray.shutdown()


class _Attempts:
    """Counts the start of every task (a Ray actor on the head node): a count past one is a retry."""

    def __init__(self) -> None:
        self.starts: dict[int, int] = {}

    def start(self, index: int) -> None:
        self.starts[index] = self.starts.get(index, 0) + 1

    def retried(self) -> int:
        return sum(n - 1 for n in self.starts.values())


def _task(fn: bytes, job: Any, index: int, attempts: Any) -> Any:
    """Count this start of task ``index``, then run ``fn`` (pickled) on ``job``. The function is
    unpickled only after the count, since that imports its module (the study's: seconds on a
    cold worker), and a worker that dies on the way is then counted as retried as well."""
    import ray
    from ray import cloudpickle

    try:
        ray.get(attempts.start.remote(index))
    except ray.exceptions.RayError:
        pass  # the count is lost with the head node; the run goes on
    return cloudpickle.loads(fn)(job)


def _retried(ray: Any, attempts: Any, before: int) -> int:
    """The retries the actor ``attempts`` counted (``before`` when it cannot be reached)."""
    try:
        return max(before, ray.get(attempts.retried.remote()))
    except ray.exceptions.RayError:
        return before


def run_tasks(
    ray: Any,
    fn: Callable[[Any], Any],
    jobs: Sequence[Any],
    lost: Callable[[Any, str], Any],
    on_retry: Callable[[int], None] = lambda retried: None,
) -> Iterator[tuple[int, Any]]:
    """Yield ``(i, fn(jobs[i]))`` for every job, each as its Ray task ends (in that order).

    ``fn`` and the jobs must be picklable (a module-level function, plain data); every machine
    of the cluster must import ``fn``'s module. A task whose worker process or node died is run
    again, up to :data:`MAX_RETRIES` times; after that its result is ``lost(job, why)``.
    ``on_retry(n)`` is told the total number of retries whenever it grows. An exception that
    ``fn`` raises is raised here (``fn`` may catch its own and return them as a result).
    """
    attempts = ray.remote(num_cpus=0, resources={'node:__internal_head__': 0.001})(_Attempts).remote()
    task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(_task)
    from ray import cloudpickle

    pickled = ray.put(cloudpickle.dumps(fn))  # once, shared by the tasks
    pending = {task.remote(pickled, job, i, attempts): i for i, job in enumerate(jobs)}
    retried = 0
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1, timeout=POLL_S)
        now = _retried(ray, attempts, retried)
        if now > retried:
            retried = now
            on_retry(retried)
        for ref in ready:
            i = pending.pop(ref)
            try:
                result = ray.get(ref)
            except ray.exceptions.RayTaskError as exc:
                raise exc.as_instanceof_cause() from None
            except ray.exceptions.RayError as exc:
                result = lost(jobs[i], f'lost after {MAX_RETRIES} retries: {type(exc).__name__}')
            yield i, result


def in_order(results: Iterator[tuple[int, Any]]) -> Iterator[Any]:
    """The results of :func:`run_tasks` in the order of their jobs (each held until those before
    it are in)."""
    held: dict[int, Any] = {}
    following = 0
    for i, result in results:
        held[i] = result
        while following in held:
            yield held.pop(following)
            following += 1


def files_of(folder: str | Path) -> dict[str, bytes]:
    """Every file under ``folder``: ``{path relative to it: its bytes}`` (to ship to another machine)."""
    root = Path(folder)
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob('*')) if p.is_file()}


def write_files(folder: str | Path, files: Mapping[str, bytes]) -> None:
    """Write the files of :func:`files_of` under ``folder``."""
    for name, data in files.items():
        path = Path(folder) / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
