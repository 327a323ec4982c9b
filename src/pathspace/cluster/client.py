"""Starting or joining a Dask cluster for pathspace's tasks."""
from __future__ import annotations

from typing import Any

from ..extras import optional_import

__all__ = ["require_distributed", "start_client", "jobqueue_cluster", "JOBQUEUE_KINDS"]

# Dask settings of the workers pathspace starts (see start_client).
WORKER_CONFIG = {"distributed.worker.profile.enabled": False}
# The batch systems of dask-jobqueue that `pathspace cluster` starts workers on.
JOBQUEUE_KINDS = {"slurm": "SLURMCluster", "pbs": "PBSCluster", "sge": "SGECluster", "lsf": "LSFCluster"}


def require_distributed():
    """The ``dask.distributed`` module, or an ImportError naming the extra that installs it."""
    return optional_import("dask.distributed", "renders on a cluster", extra="dask")


def start_client(workers: int | None = None, scheduler: str | None = None, threads_per_worker: int = 1,
                 dashboard: bool = True, **cluster_options: Any):
    """A ``dask.distributed.Client``: joined to the scheduler at ``scheduler`` ("tcp://host:8786"), or of a
    new ``LocalCluster`` of ``workers`` processes with ``threads_per_worker`` threads each (default: one
    process per core, one thread each -- pathspace's tasks scale across processes, not threads; see
    docs/distributed.md).  ``dashboard``: serve Dask's dashboard (``client.dashboard_link``) on a free
    port -- its scheduler-side monitoring costs about 5% of the workers' throughput when the client shares
    the cores with them (measured on two cores).  ``cluster_options`` go to ``LocalCluster``.
    ``client.close()`` (or leaving a ``with`` block) also stops a cluster it started."""
    distributed = require_distributed()
    import dask

    if scheduler is not None:
        if workers is not None or cluster_options:
            raise ValueError("scheduler: joins an existing cluster; workers and cluster options are not used")
        return distributed.Client(scheduler)
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers: expected a number of worker processes >= 1, got {workers!r}")
    if not isinstance(threads_per_worker, int) or threads_per_worker < 1:
        raise ValueError(f"threads_per_worker: expected an integer >= 1, got {threads_per_worker!r}")
    from .. import _native

    count = workers if workers is not None else max(1, _native.default_thread_count() // threads_per_worker)
    options = {"dashboard_address": ":0" if dashboard else None, **cluster_options}
    # Workers sample their threads' stacks every 10 ms for the dashboard's profile, holding the GIL while
    # they do: 3-4% of a render (measured on two single-threaded workers).  Their processes are started
    # here, with this setting; a client that starts its own LocalCluster also closes it when it is closed.
    with dask.config.set(WORKER_CONFIG):
        return distributed.Client(n_workers=count, threads_per_worker=threads_per_worker, processes=True,
                                  **options)


def jobqueue_cluster(kind: str, *, cores: int, memory: str, walltime: str, queue: str | None = None,
                     account: str | None = None, processes: int | None = None, **options: Any):
    """A dask-jobqueue cluster of ``kind`` ("slurm", "pbs", "sge", "lsf") whose jobs each run ``processes``
    single-threaded worker processes (default: one per core) on ``cores`` cores with ``memory``, charged to
    ``account`` (SGE and LSF call it a project); no job is submitted until it is scaled
    (``cluster.scale(jobs=n)``).  The workers' profiler is off, as in :func:`start_client`."""
    if kind not in JOBQUEUE_KINDS:
        raise ValueError(f"cluster: expected one of {', '.join(JOBQUEUE_KINDS)}, got {kind!r}")
    jobqueue = optional_import("dask_jobqueue", "clusters on batch queues", extra="dask")
    processes = cores if processes is None else processes
    if not 1 <= processes <= cores:
        raise ValueError(f"processes: expected 1 .. cores ({cores}), got {processes}")
    charge = "account" if kind in ("slurm", "pbs") else "project"
    extra = {k: v for k, v in (("queue", queue), (charge, account)) if v is not None}
    # The jobs start their workers on other machines: the setting travels as an environment variable.
    prologue = [f"export DASK_{key.upper().replace('.', '__').replace('-', '_')}={value}"
                for key, value in WORKER_CONFIG.items()]
    return getattr(jobqueue, JOBQUEUE_KINDS[kind])(cores=cores, processes=processes, memory=memory,
                                                   walltime=walltime, job_script_prologue=prologue, **extra,
                                                   **options)
