"""Where a diagnosis's and an explanation's refits run: worker processes or this one.

The refits are independent, so they go to a process pool at once; numba and BLAS are not
fork-safe, so the workers are spawned.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from pathlib import Path
from typing import Final, ParamSpec, TypeVar

import numpy as np
import numpy.typing as npt

from catheter_models.errors import CatheterError

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


@contextmanager
def refit_executor(
    workers: int | None, *, progress: bool = False, tasks: int | None = None
) -> Iterator[Executor]:
    """Where refits run; the one place :func:`diagnose` and ``explain`` choose it.

    Worker processes (``workers``, default one per core, at most ``tasks``), or this process
    for one worker or a progress bar (bars from several processes would garble each other).
    """
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
