"""Where dataset samples are made: this process, a local spawn pool, or Dask distributed.

Each runner yields ``(files, record)`` per sample index as samples finish (in any order); the
caller writes them. GL contexts never cross a ``fork``: pool workers start with ``spawn`` and
make their renderer in their initializer; Dask workers (spawned by the nanny) get their settings
from :class:`RendererPlugin` and make one renderer in the thread that runs their tasks (a GL
context is current in one thread), so one thread per worker gives one context per worker.
"""

from __future__ import annotations

import logging
import os
import threading
import traceback
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, wait
from contextlib import contextmanager
from typing import Any

from ..errors import SonarRasterError
from .config import DatasetConfig

Result = tuple[dict[str, bytes], dict]

_LOCAL = threading.local()  # this thread's renderer
_SETTINGS: dict[str, Any] = {}  # this process's renderer backend and settings


def renderer_options(config: DatasetConfig) -> tuple[str | None, dict[str, Any]]:
    """GL backend and :class:`RasterSettings` keywords from the config's ``[render]`` table."""
    options = dict(config.render)
    backend = options.pop("backend", None)
    return backend, options


def _make_renderer(backend: str | None, settings: dict[str, Any]) -> Any:
    from ..rendering.gl.raster import RasterRenderer, RasterSettings

    return RasterRenderer(backend, RasterSettings(**settings))


def _thread_renderer() -> Any:
    """Return the renderer of the calling thread, made on first use with the process's settings."""
    key = (_SETTINGS.get("backend"), tuple(sorted(_SETTINGS.get("settings", {}).items())))
    renderer = getattr(_LOCAL, "renderer", None)
    if renderer is None or getattr(_LOCAL, "key", None) != key:
        if renderer is not None:
            renderer.release()
        renderer = _make_renderer(_SETTINGS.get("backend"), _SETTINGS.get("settings", {}))
        _LOCAL.renderer, _LOCAL.key = renderer, key
    return renderer


def _configure(backend: str | None, settings: dict[str, Any]) -> None:
    _SETTINGS.update(backend=backend, settings=dict(settings))


#: Seconds between a pool worker's checks that its parent is still alive.
WATCH_PARENT_S = 0.5


def _watch_parent(parent: int) -> None:
    """Exit this worker at once when its parent process is gone (killed by SIGKILL, say)."""
    import time

    while os.getppid() == parent:
        time.sleep(WATCH_PARENT_S)
    os._exit(1)


def _init_pool_worker(backend: str | None, settings: dict[str, Any], parent: int) -> None:
    """Pool initializer: runs in the spawned worker, which makes its GL context here.

    A daemon thread watches the parent: a pool whose parent was killed outright (SIGKILL, an
    OOM kill) has nobody to send it work or to stop it, so its workers exit by themselves.
    """
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()
    _configure(backend, settings)
    _thread_renderer()


def run_one(config: DatasetConfig, seed: int, index: int, renderer: Any = None) -> Result:
    """Make one sample; any error becomes a "failed" record instead of stopping the batch.

    A :class:`SonarRasterError` (bad input: a corrupt mesh, impossible drawn values) fails the
    same way every time and is final; any other error (GL, memory) is marked ``retry`` and
    a later run makes the sample again.
    """
    from . import sample as _dataset_sample

    try:
        sample = _dataset_sample.make_sample(config, seed, index, renderer or _thread_renderer())
    except Exception as exc:  # noqa: BLE001 - recorded in the index; the batch goes on
        detail = traceback.format_exception_only(type(exc), exc)[-1].strip()
        record = {
            "index": int(index),
            "status": "failed",
            "error": detail,
            "retry": not isinstance(exc, SonarRasterError),
            "traceback": traceback.format_exc(limit=8)[-4000:],
        }
        return {}, record
    return sample.files, sample.record


def run_in_process(config: DatasetConfig, seed: int, todo: list[int]) -> Iterator[Result]:
    """One renderer in this process (used for one worker: nothing is forked)."""
    backend, settings = renderer_options(config)
    renderer = _make_renderer(backend, settings)
    try:
        for index in todo:
            yield run_one(config, seed, index, renderer)
    finally:
        renderer.release()


def _windowed(submit: Any, todo: list[int], window: int) -> Iterator[Result]:
    """Keep ``window`` tasks in flight; yield results as they finish."""
    pending: set[Future] = set()
    queue = list(reversed(todo))
    try:
        while queue or pending:
            while queue and len(pending) < window:
                pending.add(submit(queue.pop()))
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut.result()
    finally:
        for fut in pending:
            fut.cancel()


def run_pool(config: DatasetConfig, seed: int, todo: list[int], workers: int) -> Iterator[Result]:
    """A local pool of ``workers`` spawned processes, one renderer each."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    backend, settings = renderer_options(config)
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_init_pool_worker,
        initargs=(backend, settings, os.getpid()),
    )
    try:
        yield from _windowed(
            lambda i: pool.submit(run_one, config, seed, i), todo, window=2 * workers
        )
    except BrokenProcessPool:
        raise SonarRasterError(
            "a dataset worker process died (no GL context, out of memory, or a crash); "
            "check 'sonar-raster doctor', then rerun the same command to resume"
        ) from None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


class RendererPlugin:
    """Dask worker plugin: one renderer per worker, made in the thread that runs its tasks.

    A GL context is current in one thread only, so :meth:`setup` (which runs on the worker's
    event loop) stores the settings and asks the worker's task executor to make the renderer;
    with one thread per worker that is one GL context per worker, and a task that finds none
    in its thread makes one. Workers are spawned by Dask's nanny: no context crosses a fork.
    """

    name = "sonar-raster-renderer"

    def __init__(self, backend: str | None, settings: dict[str, Any]):
        self.backend, self.settings = backend, dict(settings)

    def setup(self, worker: Any) -> None:
        """Store this worker's renderer settings and make its renderer in the task thread."""
        _configure(self.backend, self.settings)
        executor = getattr(worker, "executors", {}).get("default")
        if executor is not None:
            executor.submit(_thread_renderer)  # a failure shows again in the first task

    def teardown(self, worker: Any) -> None:
        """Drop the settings; the context goes with the worker process."""
        _SETTINGS.clear()


def _dask_plugin(backend: str | None, settings: dict[str, Any]) -> Any:
    from distributed import WorkerPlugin

    cls = type("SonarRasterRendererPlugin", (RendererPlugin, WorkerPlugin), {})
    return cls(backend, settings)


@contextmanager
def dask_client(scheduler: str, workers: int) -> Iterator[Any]:
    """Connect a Dask client, quieting Dask's INFO logging meanwhile.

    ``scheduler`` is a ``tcp://`` address, or "local" for a LocalCluster of ``workers``
    processes with one thread each (closed on exit).
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SonarRasterError(
            "--scheduler needs Dask distributed; install it with "
            "'pip install sonar_raster[cluster]'"
        ) from None
    quiet = logging.getLogger("distributed")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    cluster = None
    try:
        try:
            if scheduler == "local":
                cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    silence_logs=logging.ERROR,
                )
                client = Client(cluster)
            else:
                client = Client(scheduler, timeout="10s")
        except (OSError, ValueError) as exc:  # ValueError: not an address
            raise SonarRasterError(
                f"cannot reach the Dask scheduler {scheduler}: {exc} (give 'local' or an "
                "address such as tcp://host:8786)"
            ) from None
        try:
            yield client
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()
        quiet.setLevel(level)


def run_dask(
    config: DatasetConfig, seed: int, todo: list[int], client: Any, workers: int
) -> Iterator[Result]:
    """Make samples on the Dask cluster of ``client``, ``2 x workers`` tasks in flight."""
    backend, settings = renderer_options(config)
    client.register_plugin(_dask_plugin(backend, settings))
    window = 2 * max(1, workers, len(client.scheduler_info()["workers"]))
    yield from _dask_windowed(client, config, seed, todo, window)


def _dask_windowed(
    client: Any, config: DatasetConfig, seed: int, todo: list[int], window: int
) -> Iterator[Result]:
    from distributed import as_completed

    queue = list(reversed(todo))

    def submit() -> Any:
        return client.submit(run_one, config, seed, queue.pop(), pure=False)

    running = as_completed([submit() for _ in range(min(window, len(queue)))])
    for fut in running:
        result = fut.result()
        fut.release()
        if queue:
            running.add(submit())
        yield result
