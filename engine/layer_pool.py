"""Worker processes for a laminate's layers in a process that runs threads (the GUI; issue 16).

:func:`engine.laminate.run_laminate` runs the layers' pipelines side by side in forked children, but a
process with other threads running (the GUI's workers, Qt's own) must not fork: a lock another thread
holds stays locked in the child for ever.  A :class:`LayerPool` keeps worker processes started fresh
(``multiprocessing``'s "spawn" method: a new interpreter, which also works in the frozen build, as
:mod:`engine.sandbox`), each with the pipelines' modules imported, waiting for layers.  The scheduler
sends a worker a prepared layer (pickled: the layer's job, its surface and its line), the worker runs
the layer's pipeline and answers exactly as a forked child does (:func:`engine.laminate._pipeline_answer`:
the arrays in a file the caller maps), and waits for the next one.  So the answers, and the program,
are those of one process.

Starting a worker costs an interpreter and the imports (~0.5 s of CPU): :meth:`LayerPool.warm` starts
them ahead, in the background, and they are kept between runs.  A cancelled run kills the workers still
computing (their CPU is free at once) and the pool starts fresh ones behind them.
"""

from __future__ import annotations

import threading
from typing import Any

__all__ = ["LayerPool"]


def _pool_main(conn: Any) -> None:
    """A pool worker: import the pipelines' modules, then answer layers until the pool closes its end."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the owner stops its workers itself
    from engine.laminate import _pipeline_answer, _preload, _remove_files

    _preload()
    conn.send_bytes(b"ready")
    from engine import budget

    while True:
        try:
            jp, p, upto, paths, (max_memory, materialised) = conn.recv()
        except (EOFError, OSError):
            return
        budget.set_max_memory(max_memory)           # the owner's memory budget, as a forked child has it
        budget.set_results_materialised(materialised)
        answer = _pipeline_answer(jp, p, upto, paths)
        try:
            conn.send_bytes(answer)
        except OSError:  # the owner is gone: nobody will map or remove the answer file
            _remove_files(paths)
            return


_READY_TIMEOUT_S = 120.0
"""How long a worker may take to start and import the engine before it counts as failed (s)."""


class _Worker:
    """One pool worker process and the pool's end of its connection."""

    def __init__(self, ctx: Any) -> None:
        here, there = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=_pool_main, args=(there,), daemon=True, name="winder-layer-worker")
        self.proc.start()
        there.close()
        self.conn = here
        self.ready = False

    @property
    def pid(self) -> int:
        return int(self.proc.pid or 0)

    def wait_ready(self, timeout_s: float = _READY_TIMEOUT_S) -> bool:
        """Until the worker has imported its modules; False if it died meanwhile or took longer than
        ``timeout_s`` (a hung start)."""
        if not self.ready:
            try:
                self.ready = self.conn.poll(timeout_s) and self.conn.recv_bytes() == b"ready"
            except (EOFError, OSError):
                return False
        return self.ready

    def kill(self, close_conn: bool = True) -> None:
        """Kill the process; ``close_conn`` also closes the pool's end of the connection (only the thread
        that reads it may do that: closed under a waiting reader, its descriptor could be reused by a file
        opened meanwhile; a killed worker's reader gets end-of-file instead)."""
        try:
            self.proc.kill()
        except (OSError, AttributeError, ValueError):
            pass
        try:
            self.proc.join(5.0)
        except (OSError, AssertionError, ValueError):
            pass
        if close_conn:
            try:
                self.conn.close()
            except OSError:
                pass


_MAX_FAILED_STARTS = 3
"""Workers in a row that die before they are ready after which a pool stops trying (and stays closed)."""


class LayerPool:
    """Up to ``workers`` spawned worker processes for :func:`engine.laminate.run_laminate`
    (``pool=``).  Thread-safe; :meth:`close` stops them (also at interpreter exit)."""

    def __init__(self, workers: int) -> None:
        import multiprocessing

        self.workers = max(1, int(workers))
        self._ctx = multiprocessing.get_context("spawn")
        self._lock = threading.Lock()
        self._idle: list[_Worker] = []
        self._busy: set[_Worker] = set()
        self._closed = False
        self._failed_starts = 0  # workers in a row that died before they were ready
        import atexit

        atexit.register(self.close)

    def warm(self) -> None:
        """Start the idle workers the pool may hold (in the background: the caller does not wait)."""
        with self._lock:
            if self._closed:
                return
            for _ in range(self.workers - len(self._idle) - len(self._busy)):
                try:
                    self._idle.append(_Worker(self._ctx))
                except Exception:  # noqa: BLE001 - no process (refused, cannot start): layers run in the caller
                    break

    def acquire(self) -> _Worker | None:
        """A worker ready for a layer (a new one if none is idle and fewer than ``workers`` run), or None."""
        with self._lock:
            if self._closed or len(self._busy) >= self.workers:
                return None
            w = self._idle.pop(0) if self._idle else None
            if w is None:
                try:
                    w = _Worker(self._ctx)
                except Exception:  # noqa: BLE001 - as in warm()
                    return None
            self._busy.add(w)
        if not w.wait_ready():
            with self._lock:
                self._failed_starts += 1
                give_up = self._failed_starts >= _MAX_FAILED_STARTS
            if give_up:  # workers cannot start here (a broken install): no more tries, layers run in the caller
                self.close()
            else:
                self.discard(w)
            return None
        with self._lock:
            self._failed_starts = 0
        return w

    def release(self, w: _Worker) -> None:
        """``w`` answered: idle again."""
        with self._lock:
            self._busy.discard(w)
            if self._closed or not w.proc.is_alive():
                w.kill()
            else:
                self._idle.append(w)

    def discard(self, w: _Worker) -> None:
        """``w`` was stopped mid-layer (a cancel) or died: killed; a fresh one is started behind it."""
        with self._lock:
            self._busy.discard(w)
            closed = self._closed
        w.kill()
        if not closed:
            threading.Thread(target=self.warm, daemon=True, name="winder-layer-pool-warm").start()

    def close(self) -> None:
        """Stop every worker (idempotent).  A busy worker's connection is left to the thread reading its
        answer (it gets end-of-file, and :meth:`discard` or :meth:`release` closes it)."""
        with self._lock:
            self._closed = True
            idle, busy = self._idle, list(self._busy)
            self._idle = []
        for w in idle:
            w.kill()
        for w in busy:
            w.kill(close_conn=False)

    def pids(self) -> list[int]:
        """The process ids of the workers alive (tests, diagnostics)."""
        with self._lock:
            return [w.pid for w in (*self._idle, *self._busy) if w.proc.is_alive()]


class PoolChild:
    """A layer running in a pool worker, with the interface of :class:`engine.laminate._Child`."""

    def __init__(self, pool: LayerPool, worker: _Worker, p: Any, paths: list[str], message: bytes) -> None:
        """Send ``message`` (:meth:`message`) to ``worker``; raises OSError when the worker is gone."""
        self.pool, self.worker, self.layer, self.paths = pool, worker, p, paths
        self.pid, self.fd = worker.pid, worker.conn.fileno()
        self.done = False
        worker.conn.send_bytes(message)

    @staticmethod
    def message(jp: str | None, p: Any, upto: str, paths: list[str],
                budget_state: tuple[int | None, bool] = (None, False)) -> bytes:
        """The request for a worker, pickled as the connection would pickle it (raises what pickling raises:
        a layer that will not pickle is the caller's to run, the worker stays healthy)."""
        from multiprocessing.reduction import ForkingPickler

        return bytes(ForkingPickler.dumps((jp, p, upto, paths, budget_state)))

    def ready(self) -> bool:
        """Whether it has answered (or died)."""
        return self.done or bool(self.worker.conn.poll(0))

    def receive(self) -> Any:
        """Its answer, as :meth:`engine.laminate._Child.receive`; None when the worker died."""
        import pickle

        from engine.laminate import _unpack

        try:
            raw = self.worker.conn.recv_bytes()
        except (EOFError, OSError):
            self._stop()
            return None
        self.done = True
        self.pool.release(self.worker)
        try:
            data, path, spans = pickle.loads(raw)
            return _unpack(data, path, spans)
        except Exception:  # noqa: BLE001 - a truncated answer: the layer is run again by the caller
            return None
        finally:
            self.remove_files()

    def _stop(self) -> None:
        if not self.done:
            self.done = True
            self.pool.discard(self.worker)

    def reap(self, kill: bool = True) -> None:
        if kill:
            self._stop()

    def remove_files(self) -> None:
        from engine.laminate import _remove_files

        _remove_files(self.paths)

    def close(self) -> None:
        """Stop it if it is still computing, remove its files (idempotent)."""
        self._stop()
        self.remove_files()
