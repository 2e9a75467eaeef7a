"""Where a diagnosis's and an explanation's refits run: worker processes, this one, or Ray.

The refits are independent, so they go to a process pool at once; numba and BLAS are not
fork-safe, so the workers are spawned. Where one machine is not enough, the same refits go
to a Ray cluster (:class:`RayExecutor`, ``--ray ADDRESS``): Ray is an optional extra
(``pip install 'catheter_models[ray]'``), never needed by the graph, and the local process
pool stays the default. The answers are the same either way: each refit is a pure function
of its arguments, whichever process runs it.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Final, ParamSpec, TypeVar

import numpy as np
import numpy.typing as npt

from catheter_models.errors import CatheterError, ParameterError

BoolArray = npt.NDArray[np.bool_]

P = ParamSpec("P")
T = TypeVar("T")


def default_workers() -> int:
    """Processes for a diagnosis's refits: one per core the machine lets this process use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


class RefitWorkerError(CatheterError):
    """A worker process died while refitting (killed, most often for memory)."""


_PACKAGE_ROOT: Final = str(Path(__file__).resolve().parents[2])
"""The directory this package is imported from (``src/catheter_models`` in a checkout)."""


def lab_pool(workers: int) -> ProcessPoolExecutor:
    """A pool for :func:`diagnose`'s refits (spawned: numba and BLAS are not fork-safe).

    A spawned worker starts with this process's ``sys.path`` and imports this package afresh
    to unpickle its tasks. A directory of the same name earlier on that path shadows the
    package there though not here, where it is already imported: pytest puts ``tests/``,
    which holds ``tests/catheter_models``, first, and every refit failed in the full suite.
    So each worker first puts the package's root at the front of its own path, with a
    builtin initializer that needs no import.
    """
    return ProcessPoolExecutor(
        workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=exec,
        initargs=(f"import sys; sys.path.insert(0, {_PACKAGE_ROOT!r})",),
    )


class _Serial(Executor):
    """Runs each task at once, in this process (one worker, or a progress bar to show)."""

    def submit(self, fn: Callable[P, T], /, *args: P.args, **kwargs: P.kwargs) -> Future[T]:
        future: Future[T] = Future()
        future.set_result(fn(*args, **kwargs))
        return future


RAY_LOCAL: Final = "local"
"""``--ray local``: start a Ray on this machine for the run (tests, trying it out)."""

RAY_INSTALL: Final = "pip install 'catheter_models[ray]' (Ray 2.60: 240 MB installed)"


class RayExecutor(Executor):
    """Tasks as Ray tasks, on the cluster at ``address`` or on a Ray started here.

    ``address`` is what :func:`ray.init` takes (``auto``: the cluster this machine belongs
    to; ``ray://host:10001``: a remote one through Ray Client) or :data:`RAY_LOCAL`. A Ray
    this executor started is shut down with it; one already running in this process (a
    caller's) is used and left running. A cluster gets this package's own source with the
    job (Ray's ``py_modules``), and ``modules``, further package directories the tasks import
    (the foreign plants of the lab's benchmark), so its nodes need only the dependencies
    (numpy, scipy, numba, scikit-learn; torch for the recurrent reference), not this
    checkout. A Ray started here imports them where this process does (its numba caches
    are warm there).

    Raises:
        ParameterError: Ray is not installed, or no cluster answers at ``address``.
    """

    def __init__(self, address: str, *, modules: Sequence[Path] = ()) -> None:
        try:
            import ray
        except ImportError as exc:
            raise ParameterError(
                f"--ray {address}: Ray is not installed; it is an optional extra: {RAY_INSTALL}"
            ) from exc
        self._ray: Any = ray
        self._remote: dict[Callable[..., Any], Any] = {}
        self._started = not ray.is_initialized()
        if not self._started:
            return
        options: dict[str, Any] = {
            "include_dashboard": False,
            "log_to_driver": False,  # a refit prints nothing a person needs from each node
            "logging_level": "ERROR",
        }
        if address == RAY_LOCAL:
            # A Ray on this machine shares its memory with the run: keep its object store small
            # (a refit's arguments are a few MB; Ray's default takes 30 % of the memory).
            options["object_store_memory"] = 256 * 1024 * 1024
            roots = [str(Path(m).resolve().parent) for m in modules]
            if roots:
                path = os.pathsep.join([*roots, os.environ.get("PYTHONPATH", "")])
                path = path.rstrip(os.pathsep)
                options["runtime_env"] = {"env_vars": {"PYTHONPATH": path}}
        else:
            options["address"] = address
            package = str(Path(__file__).resolve().parents[1])
            options["runtime_env"] = {"py_modules": [package, *(str(m) for m in modules)]}
        try:
            ray.init(**options)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            raise ParameterError(f"--ray {address}: no Ray cluster answered ({exc})") from exc

    def submit(self, fn: Callable[P, T], /, *args: P.args, **kwargs: P.kwargs) -> Future[T]:
        """``fn(*args, **kwargs)`` as a Ray task; its result (or error) through a future."""
        remote = self._remote.get(fn)
        if remote is None:
            remote = self._remote[fn] = self._ray.remote(fn)
        future: Future[T] = remote.remote(*args, **kwargs).future()
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Shut down the Ray this executor started (one it found running is left alone)."""
        if self._started:
            self._ray.shutdown()
            self._started = False


@contextmanager
def refit_executor(
    workers: int | None,
    *,
    progress: bool = False,
    tasks: int | None = None,
    ray: str | None = None,
) -> Iterator[Executor]:
    """Where refits run; the one place :func:`diagnose` and ``explain`` choose it.

    Ray tasks where ``ray`` names a cluster (:class:`RayExecutor`); else worker processes
    (``workers``, default one per core, at most ``tasks``), or this process for one worker or
    a progress bar (bars from several processes would garble each other).
    """
    if ray:
        with RayExecutor(ray) as executor:
            yield executor
        return
    n = workers or default_workers()
    if tasks is not None:
        n = min(n, tasks)
    if progress or n <= 1:
        yield _Serial()
        return
    with lab_pool(n) as pool:
        try:
            yield pool
        except BrokenProcessPool as exc:
            # The pool's own message names no cause and no way out; a person needs both.
            raise RefitWorkerError(
                f"a refit's worker process stopped before it answered ({exc}): it was killed, "
                "most often for memory; run again with --workers 1 (refits in this process) "
                "or with more memory free"
            ) from exc
