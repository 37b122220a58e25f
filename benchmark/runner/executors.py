"""Where a run's tasks execute: here, one after another (`local`), or on a Ray cluster (`ray`).

Both run the same task functions on the same inputs and read and write the same artifacts, so a
grid gives the same rows on either. Ray is an optional extra (`pip install ".[ray]"`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import torch
from tqdm.auto import tqdm

from benchmark.runner.diagnostics.native_memory import release_free_memory
from benchmark.runner.planning import Task
from benchmark.runner.config import RunConfig
from benchmark.runner.tasks import TaskResult, execute

log = logging.getLogger(__name__)


# Called with each task and its result as soon as it completes (the runner writes the rows so far).
OnResult = Callable[[Task, TaskResult], None]


class Executor(Protocol):
    def run(self, tasks: list[Task], cfg: RunConfig, directory: Path,
            on_result: OnResult | None = None) -> dict[str, TaskResult]: ...


class LocalExecutor:
    """Tasks in plan order, in this process, which hands the memory each task freed back to the
    system before the next starts (``native_memory.release_free_memory``)."""

    def run(self, tasks: list[Task], cfg: RunConfig, directory: Path,
            on_result: OnResult | None = None) -> dict[str, TaskResult]:
        results = {}
        for task in tqdm(tasks, desc="tasks", unit="task"):
            results[task.key] = execute(task, cfg, directory)
            if on_result is not None:
                on_result(task, results[task.key])
            release_free_memory()
        return results


def _remote_execute(task: Task, cfg: RunConfig, directory: Path, threads: int, *_deps: object) -> TaskResult:
    # Same intra-op thread count as the driver: float reductions, hence the numbers, stay identical.
    torch.set_num_threads(threads)
    try:
        return execute(task, cfg, directory)
    finally:
        release_free_memory()  # the worker process lives on for the next task


class RayExecutor:
    """Each task a Ray task declaring its CPU/GPU needs, retried when its worker dies.

    `address` is None to start a local Ray instance, or "auto" / "ray://HOST:PORT" to join a
    cluster; every node must see `cfg.cache_dir` (a shared filesystem).
    """

    def __init__(self, address: str | None = None, max_retries: int = 3):
        try:
            import ray
        except ImportError:
            raise RuntimeError('the Ray executor needs Ray: pip install ".[ray]" (or pip install "ray>=2.9")') from None
        self.ray = ray
        self.address = address
        self.max_retries = max_retries

    def run(self, tasks: list[Task], cfg: RunConfig, directory: Path,
            on_result: OnResult | None = None) -> dict[str, TaskResult]:
        ray = self.ray
        started_here = not ray.is_initialized()
        if started_here:
            # Passive OpenMP waits: tasks sharing cores must not burn them spinning.
            ray.init(address=self.address, include_dashboard=False, logging_level=logging.WARNING,
                     log_to_driver=False, runtime_env={"env_vars": {"OMP_WAIT_POLICY": "PASSIVE"}})
        try:
            remote = ray.remote(_remote_execute)
            threads = torch.get_num_threads()
            total = ray.cluster_resources().get("CPU", 1)
            refs: dict[str, object] = {}
            for task in tasks:
                deps = [refs[d] for d in task.deps]  # Ray starts a task once its inputs exist
                # Every task computes with the driver's thread count, so it asks for that many CPUs.
                refs[task.key] = remote.options(num_cpus=min(max(task.cpus, threads), total), num_gpus=task.gpus,
                                                max_retries=self.max_retries, retry_exceptions=False
                                                ).remote(task, cfg, directory, threads, *deps)
            pending = list(refs.values())
            task_of = {ref: task for task, ref in zip(tasks, refs.values())}  # ObjectRefs hash by their id
            with tqdm(total=len(pending), desc="tasks (ray)", unit="task") as bar:
                while pending:
                    done, pending = ray.wait(pending, num_returns=1)
                    finished = ray.get(done)  # surfaces a failed task at once
                    if on_result is not None:
                        for ref, result in zip(done, finished):
                            on_result(task_of[ref], result)
                    bar.update(len(done))
            return {key: ray.get(ref) for key, ref in refs.items()}
        finally:
            if started_here:
                ray.shutdown()


def get(name: str) -> Executor:
    """`local`, `ray` (a local Ray instance, or the cluster in RAY_ADDRESS), or `ray://HOST:PORT`."""
    if name == "local":
        return LocalExecutor()
    if name == "ray":
        return RayExecutor(address=None)
    if name.startswith("ray://") or name == "ray:auto":
        return RayExecutor(address="auto" if name == "ray:auto" else name)
    raise ValueError(f"unknown executor {name!r}; valid: local, ray, ray:auto, ray://HOST:PORT")
