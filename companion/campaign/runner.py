"""Running a campaign: batches of encounters on a local process pool or a Dask cluster, rows
stored as they finish, stopped when every ratio has converged.

The driver cuts the ids into batches of ``batch_pairs`` (batch ``k`` holds ids ``k B .. k B + B - 1``)
and hands out the batches not yet stored, in order, keeping every worker busy. Each worker
process holds one ``CampaignWorker`` (``_context``), built and warmed once (numba compiled,
missions planned, unmitigated flights flown): on the local pool by the pool's initializer, on a
Dask cluster (``--cluster tcp://HOST:8786``, real ``dask scheduler`` / ``dask worker``
processes) by ``Client.run`` before the first task. Whatever runs them, a batch's rows are the
same (``companion.campaign.flying``): each worker runs its BLAS on one thread, as a Dask worker
does, since a multi-threaded one sums in another order.

Every ``check_every`` encounters, on the rows stored so far in id order without a gap, the
driver checks convergence: the NMAC and LoWC risk ratios of each traffic kind present
(drone-scale, rotorcraft, fixed-wing) must be stable within ``tolerance``
(``companion.campaign.stats.is_converged``). It stops then, once ``min_pairs`` are flown, or at
``max_pairs``.
"""

from __future__ import annotations

import concurrent.futures as futures
import logging
import multiprocessing
import os
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass

from companion.campaign.flying import CampaignWorker
from companion.campaign.spec import CampaignSpec, SpecError
from companion.campaign.stats import is_converged
from companion.campaign.store import CampaignStore
from companion.campaign.summary import event_convergence
from companion.config import Settings, settings_from_dict
from heli_common.typed_config import from_dict

__all__ = ["CampaignRun", "RunProgress", "RatioVerdict", "run_batch", "convergence_verdicts", "worker_context"]

log = logging.getLogger(__name__)

_CONTEXT: dict[str, CampaignWorker] = {}
#: Worker processes run their BLAS on one thread (Dask's workers do): the same sums, the same rows.
BLAS_THREADS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _spec_from_text(text: str) -> CampaignSpec:
    return from_dict(CampaignSpec, tomllib.loads(text), "", SpecError)


def _settings_from_text(text: str) -> Settings:
    return settings_from_dict(tomllib.loads(text)) if text else Settings()


def worker_context(spec_text: str, settings_text: str, digest: str) -> CampaignWorker:
    """This process's worker for a spec (built and warmed on first use)."""
    worker = _CONTEXT.get(digest)
    if worker is None:
        for name in ("companion", "heli_model"):
            logging.getLogger(name).setLevel(logging.ERROR)  # a decision logs a warning: not here
        worker = CampaignWorker(_spec_from_text(spec_text), _settings_from_text(settings_text), digest)
        worker.warm()
        _CONTEXT.clear()
        _CONTEXT[digest] = worker
    return worker


def warm_worker(spec_text: str, settings_text: str, digest: str) -> int:
    """Warm this process (a pool initializer, or ``Client.run`` on each Dask worker)."""
    worker_context(spec_text, settings_text, digest)
    return os.getpid()


def run_batch(first_id: int, n: int, spec_text: str, settings_text: str, digest: str) -> tuple[int, list[dict]]:
    """One task: the rows of encounters ``first_id .. first_id + n - 1``."""
    worker = worker_context(spec_text, settings_text, digest)
    return first_id, [worker.row(i) for i in range(first_id, first_id + n)]


def convergence_verdicts(table, tolerance: float) -> dict[str, object]:
    """The verdict of every ratio the campaign stops on: ``{"drone nmac": Verdict, ...}``; each
    verdict also carries ``ratio``, the running ratio's last value."""
    out = {}
    traffic = table.column("traffic").to_pylist()
    for kind in sorted(set(traffic)):
        rows = table.filter([t == kind for t in traffic])
        for metric in ("nmac", "lowc"):
            curve = event_convergence(rows, metric)
            verdict = is_converged(curve, tol=tolerance)
            out[f"{kind} {metric}"] = RatioVerdict(
                verdict.converged, verdict.reason, float(curve.ratio[-1]) if len(curve.ratio) else float("nan")
            )
    return out


@dataclass(frozen=True)
class RatioVerdict:
    """A ratio's convergence verdict and its current value."""

    converged: bool
    reason: str
    ratio: float


@dataclass
class RunProgress:
    """What a running campaign reports to its progress display."""

    done: int
    total: int
    started_s: float
    pairs_per_s: float
    ratios: dict
    converged: bool


class CampaignRun:
    """One run of a campaign into a directory (resumes what is there).

    Parameters
    ----------
    spec : CampaignSpec
    store : CampaignStore
    settings_text : str
        The companion settings file's text ("" for the defaults).
    workers : int
        Local worker processes (default: every core).
    cluster : str, optional
        A Dask scheduler's address; the batches run there.
    progress : callable (RunProgress) -> None, optional
    """

    def __init__(
        self,
        spec: CampaignSpec,
        store: CampaignStore,
        settings_text: str = "",
        *,
        workers: int | None = None,
        cluster: str | None = None,
        progress: Callable[[RunProgress], None] | None = None,
        max_pairs: int | None = None,
    ) -> None:
        self.spec = spec
        self.store = store
        self.settings_text = settings_text
        self.digest = store.open(spec, settings_text)
        self.workers = workers or os.cpu_count() or 1
        self.cluster = cluster
        self.progress = progress
        self.max_pairs = min(max_pairs or spec.max_pairs, spec.max_pairs)
        self.spec_text = store.root.joinpath("spec.toml").read_text()

    # ------------------------------------------------------------------ batches
    def pending(self) -> list[tuple[int, int]]:
        """(first id, count) of the batches not stored yet, in order."""
        done = self.store.done_batches()
        b = self.spec.batch_pairs
        return [(first, min(b, self.max_pairs - first)) for first in range(0, self.max_pairs, b) if first not in done]

    def _contiguous(self, done: set[int]) -> int:
        n, b = 0, self.spec.batch_pairs
        while n < self.max_pairs and n in done:
            n += b
        return min(n, self.max_pairs)

    def check(self) -> tuple[bool, dict]:
        """(stop now, verdicts) on the rows stored without a gap."""
        n = self._contiguous(self.store.done_batches())
        if n == 0:
            return False, {}
        table = self.store.table()
        table = table.filter([i < n for i in table.column("id").to_pylist()])
        verdicts = convergence_verdicts(table, self.spec.tolerance)
        stop = n >= self.spec.min_pairs and all(v.converged for v in verdicts.values())
        return stop, verdicts

    # ------------------------------------------------------------------ running
    def run(self) -> dict:
        """Fly the pending batches until converged or ``max_pairs``; returns a summary of the run."""
        pending = self.pending()
        t0 = time.perf_counter()
        done_before = self.max_pairs - sum(n for _, n in pending)
        flown = 0
        stop, verdicts = self.check()
        if not stop and pending:
            self.store.log_run({"event": "start", "workers": self.workers, "cluster": self.cluster or ""})
            submit, close = self._executor()
            try:
                flown, stop, verdicts = self._drive(pending, submit, done_before, t0)
            except BaseException as exc:  # killed (Ctrl-C) or failed: say so, keep the parts
                self.store.log_run(
                    {
                        "event": "interrupted",
                        "reason": type(exc).__name__,
                        "stored": self._contiguous(self.store.done_batches()),
                        "wall_s": time.perf_counter() - t0,
                    }
                )
                raise
            finally:
                close()
        wall = time.perf_counter() - t0
        result = {
            "event": "end",
            "flown": flown,
            "stored": self._contiguous(self.store.done_batches()),
            "wall_s": wall,
            "workers": self.workers,
            "cluster": self.cluster or "",
            "pairs_per_s": flown / wall if wall > 0 else 0.0,
            "converged": stop,
            "verdicts": {k: v.reason if not v.converged else "converged" for k, v in verdicts.items()},
        }
        self.store.log_run(result)
        return result

    def _drive(self, pending, submit, done_before: int, t0: float):
        queue = list(pending)
        running: dict = {}
        flown, since_check, stop, verdicts = 0, 0, False, {}
        while (queue or running) and not stop:
            while queue and len(running) < 2 * self.workers:
                first, n = queue.pop(0)
                running[submit(first, n)] = (first, n)
            finished, _ = futures.wait(list(running), return_when=futures.FIRST_COMPLETED)
            for fut in finished:
                first, n = running.pop(fut)
                got_first, rows = fut.result()
                self.store.append(got_first, rows)
                flown += n
                since_check += n
            if since_check >= self.spec.check_every or not (queue or running):
                since_check = 0
                stop, verdicts = self.check()
            if self.progress is not None:
                wall = time.perf_counter() - t0
                self.progress(
                    RunProgress(done_before + flown, self.max_pairs, t0, flown / max(wall, 1e-9), verdicts, stop)
                )
        for fut in running:
            fut.cancel()
        return flown, stop, verdicts

    def _executor(self):
        args = (self.spec_text, self.settings_text, self.digest)
        if self.cluster:
            from distributed import Client

            client = Client(self.cluster, timeout="30s")
            client.run(warm_worker, *args)
            workers = len(client.scheduler_info()["workers"])
            self.workers = max(workers, 1)
            log.info("campaign on %s: %d Dask workers warmed", self.cluster, workers)

            def submit(first, n):
                return client.submit(run_batch, first, n, *args, pure=False)

            def close():
                client.close()

            return _DaskFutures(submit), close
        for var in BLAS_THREADS:  # as a Dask worker's: a multi-threaded BLAS sums in another order
            os.environ[var] = "1"
        pool = futures.ProcessPoolExecutor(
            self.workers, mp_context=multiprocessing.get_context("spawn"), initializer=warm_worker, initargs=args
        )

        def submit_local(first, n):
            return pool.submit(run_batch, first, n, *args)

        return submit_local, lambda: pool.shutdown(cancel_futures=True)


class _DaskFutures:
    """Dask futures as ``concurrent.futures`` ones (``futures.wait`` needs those)."""

    def __init__(self, submit) -> None:
        self._submit = submit

    def __call__(self, first: int, n: int):
        dask_future = self._submit(first, n)
        fut: futures.Future = futures.Future()

        def relay(f) -> None:
            try:
                fut.set_result(f.result())
            except BaseException as exc:  # noqa: BLE001 - handed to the driver
                fut.set_exception(exc)

        dask_future.add_done_callback(relay)
        fut._dask = dask_future  # keep it alive while it runs
        return fut
