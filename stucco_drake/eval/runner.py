"""Run a table's independent runs on any ``concurrent.futures.Executor``, resumably.

Finished runs are appended to the results file as they complete, so an interrupted table
(killed, or a worker that died) resumes by rerunning the same command: recorded runs are
skipped.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import sys
import threading
import time
from collections.abc import Callable, Iterable

from stucco_drake.eval.results import RunResults, row_key


class RunInterrupted(RuntimeError):
    """The table stopped before all runs finished; what finished is recorded."""


def _worker_died(error: BaseException) -> bool:
    # Process pools raise BrokenProcessPool; Dask reports a worker lost mid-task as KilledWorker
    # (matched by name so that Dask stays optional).
    return isinstance(error, cf.BrokenExecutor) or type(error).__name__ == "KilledWorker"


class Progress:
    """A one-line progress bar redrawn with ``\\r`` on ``stream`` (stderr by default)."""

    def __init__(self, total: int, label: str = "runs", stream=None, width: int = 30):
        self.total, self.label, self.width = total, label, width
        self.stream = sys.stderr if stream is None else stream
        self.count = 0
        self.start = time.perf_counter()
        self._draw()

    def advance(self) -> None:
        self.count += 1
        self._draw()

    def _draw(self) -> None:
        if self.stream is False:
            return
        filled = self.width * self.count // max(self.total, 1)
        elapsed = time.perf_counter() - self.start
        eta = (
            f"{elapsed / self.count * (self.total - self.count):5.0f} s" if self.count else "    ?"
        )
        self.stream.write(
            f"\r{self.label} [{'#' * filled}{'.' * (self.width - filled)}] "
            f"{self.count}/{self.total} {elapsed:5.0f} s, eta {eta} "
        )
        self.stream.flush()

    def close(self) -> None:
        if self.stream is not False:
            self.stream.write("\n")
            self.stream.flush()


def run_table(
    tasks: Iterable[tuple[str, int, str]],
    run_one: Callable[[tuple[str, int, str]], dict],
    results: RunResults,
    executor: cf.Executor,
    progress=None,
) -> int:
    """Run every task not yet in ``results`` on ``executor``; record each as it finishes.

    Args:
        tasks: run keys (scene, seed, method).
        run_one: picklable (module-level) function of a key returning its row (with that key).
        results: the results file.
        executor: any ``concurrent.futures.Executor`` (process pool, Dask, ...).
        progress: stream for the progress bar (stderr by default; False for none).

    Returns:
        The number of runs recorded by this call.

    Raises:
        RunInterrupted: a worker died or a run raised; every run that finished is recorded,
            and rerunning resumes with the rest.
    """
    done = results.done()
    todo = list(dict.fromkeys(task for task in tasks if tuple(task) not in done))
    bar = Progress(len(todo), stream=progress)
    futures = {executor.submit(run_one, task): task for task in todo}
    recorded, died, failed = 0, None, []
    try:
        for future in cf.as_completed(futures):
            task = futures[future]
            try:
                row = future.result()
            except Exception as error:
                # Keep collecting: the runs that finished elsewhere must still be recorded.
                if _worker_died(error):
                    died = died or error
                else:
                    failed.append((task, error))
                continue
            if row_key(row) != tuple(task):
                failed.append((task, ValueError(f"run_one returned the row of {row_key(row)}")))
                continue
            recorded += results.append(row)
            bar.advance()
    finally:
        bar.close()
    missing = len(todo) - recorded
    if died is not None:
        raise RunInterrupted(
            f"a worker process died ({type(died).__name__}); {recorded} runs recorded, "
            f"{missing} not: rerun the same command to resume"
        ) from died
    if failed:
        task, error = failed[0]
        raise RunInterrupted(
            f"run {task} failed ({type(error).__name__}: {str(error).splitlines()[0]}); "
            f"{len(failed)} failed, {recorded} recorded: fix and rerun to resume"
        ) from error
    return recorded


def _exit_with_parent() -> None:
    """Process-pool initializer: end this worker as soon as the process that started the pool
    ends, killed included. Otherwise a stopped table's workers run on, simulating episodes and
    writing their logs into the folder for a table nobody is running."""
    parent = multiprocessing.parent_process()
    if parent is None:  # not started by multiprocessing: nothing to watch
        return

    def watch():
        parent.join()  # returns when the parent's end of the sentinel pipe closes
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def make_executor(kind: str = "process", workers: int | None = None, scheduler: str | None = None):
    """An executor for :func:`run_table`.

    Args:
        kind: "process" (a local process pool) or "dask" (a Dask cluster's executor).
        workers: processes of the pool (default: one per CPU), each ended when the calling
            process ends, however it ends; for "dask" without a scheduler, the workers of
            the local cluster it starts.
        scheduler: a Dask scheduler address ("tcp://host:8786"); None starts a local cluster.
            Workers must see the same file system (episode logs are read by path).
    """
    if kind == "process":
        # Spawned, not forked: a forked child inherits Drake's and BLAS's threads in an
        # undefined state. Each worker ends with the table's process.
        return cf.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                      initializer=_exit_with_parent)
    if kind == "dask":
        try:
            from dask.distributed import Client
        except ImportError:
            raise RuntimeError(
                "the dask executor needs Dask: pip install 'stucco_drake[dask]'"
            ) from None
        if scheduler is not None:
            client = Client(scheduler)
        else:
            # A local cluster only for this machine: loopback, no dashboard server.
            client = Client(
                n_workers=workers, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
            )
        executor = client.get_executor()
        executor.client = client  # keeps the client alive with the executor; closed on shutdown
        original = executor.shutdown

        def shutdown(wait=True, **kwargs):
            original(wait=wait)
            client.close()

        executor.shutdown = shutdown
        return executor
    raise ValueError(f"unknown executor kind {kind!r} (known: process, dask)")
