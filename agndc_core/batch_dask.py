"""The Dask engine of ``batch.remesh_many`` (``agndc batch --engine dask``).

Imported only when that engine is chosen: ``dask[distributed]`` is an optional extra
(``pip install 'agndc-remesher[dask]'``). The jobs are ``batch_job.run_job`` calls on the cluster's
workers, which read the inputs and write the outputs themselves (paths are absolute, so the
workers need the same filesystem, and ``agndc_core`` installed). A ``WorkerPlugin`` prepares
every worker once, also workers that join later: torch's share of the host's cores and the
network in the per-process model cache; nothing but a path and the options travels per task.
Results come back in completion order to ``on_rows``; a worker that dies has its tasks retried
by Dask, and a task that keeps killing workers ends as ``KilledWorker``, a failed row.
"""

from __future__ import annotations

from collections import Counter

from .batch_job import failed_row, prepare_worker, run_job
from .errors import AGNDCError
from .options import RemeshOptions

try:
    import dask
    from dask.system import CPU_COUNT
    from distributed import Client, LocalCluster, as_completed
    from distributed.comm.addressing import get_address_host
    from distributed.diagnostics.plugin import WorkerPlugin
except ImportError as exc:
    raise AGNDCError("--engine dask needs Dask distributed, an optional extra: "
                     f"pip install 'agndc-remesher[dask]' ({exc})") from None

PLUGIN_NAME = "agndc-remesher"
#: how long to wait for a scheduler given by address
CONNECT_TIMEOUT = "30s"
#: dask config key of an environment variable the nanny sets in new workers (None: not set)
NO_MALLOC_TRIM = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"


class PrepareWorker(WorkerPlugin):
    """Runs ``batch_job.prepare_worker`` on every worker as it starts (or at registration).

    Torch threads per task: ``options.threads`` if given, else the worker host's cores divided by
    the task threads of all workers on that host (``host_threads``, counted at registration;
    hosts that join later count this worker's own threads), so the host is not oversubscribed.
    """

    def __init__(self, options: RemeshOptions, host_threads: dict[str, int]):
        self.options, self.host_threads = options, host_threads

    def setup(self, worker) -> None:
        sharing = self.host_threads.get(get_address_host(worker.address), worker.state.nthreads)
        threads = self.options.threads or max(1, CPU_COUNT // max(1, sharing))
        try:
            prepare_worker(self.options, threads)
        except AGNDCError:
            pass  # each task meets the same error in remesh and reports it in its own row


def run_dask(jobs, options: RemeshOptions, workers: int, scheduler: str | None,
             on_rows) -> None:
    """Run ``jobs`` on the cluster at ``scheduler``, or on a new ``LocalCluster`` of ``workers``
    single-threaded processes; ``on_rows(job, rows)`` gets each job's rows as its task ends."""
    if not jobs:
        return
    cluster = None
    try:
        if scheduler:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        else:
            # the nanny's default MALLOC_TRIM_THRESHOLD_ (which also fixes glibc's mmap
            # threshold) made the network's many large temporaries about 15 % slower here
            with dask.config.set({NO_MALLOC_TRIM: None}):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                       processes=True, dashboard_address=None)
            client = Client(cluster)
    except (OSError, TimeoutError) as exc:
        if cluster is not None:
            cluster.close()
        raise AGNDCError(f"cannot reach the Dask scheduler {scheduler or '(local)'}: "
                         f"{exc}") from None
    futures = []
    try:
        client.register_plugin(PrepareWorker(options, _host_threads(client)), name=PLUGIN_NAME)
        futures = client.map(run_job, jobs, options=options, pure=False)
        job_of = {future.key: job for future, job in zip(futures, jobs, strict=True)}
        for future in as_completed(futures):
            job = job_of[future.key]
            if future.status == "finished":
                on_rows(job, future.result())
            else:
                exc = future.exception()
                on_rows(job, [failed_row(job, options, f"{type(exc).__name__}: {exc}")])
            future.release()
    except BaseException:
        if futures:
            client.cancel(futures)
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _host_threads(client) -> dict[str, int]:
    """Task threads of all workers per host, e.g. {"10.0.0.5": 8}."""
    counts = Counter()
    for worker in client.scheduler_info()["workers"].values():
        counts[worker["host"]] += int(worker["nthreads"])
    return dict(counts)
