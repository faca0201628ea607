"""One BLAS thread for work made of many small products (no bpy).

A live re-solve (pipeline.prepared.PreparedScene.live) is hundreds of small products, fits and
factorisations (tens to hundreds of targets by a few hundred lights). With OpenBLAS's second
thread each of them pays the threads' hand-over, and the thread spins on the core Blender's main
thread draws and paints on: bench_live.py measured the living room's strokes at 99-197 ms with
numpy's and scipy's default threads (two here), 91-103 ms with this limit and 84-99 ms with
OPENBLAS_NUM_THREADS=1 for the whole process (docs/benchmarks.md, "Live").

``one_blas_thread()`` limits the BLAS libraries loaded in the process (numpy's and scipy's
OpenBLAS, or MKL, BLIS, ...) to one thread for its span, through threadpoolctl (bundled with the
extension and pinned in requirements.txt); the limit is the process's, restored on leaving.
Without threadpoolctl it changes nothing and says so (``AVAILABLE``). The cold solve's large
factorisations keep every thread.
"""
from __future__ import annotations

import contextlib
import threading

try:
    from threadpoolctl import ThreadpoolController
except ImportError:  # (a Python without it: BLAS keeps its threads)
    ThreadpoolController = None

__all__ = ["AVAILABLE", "one_blas_thread", "controller"]

#: whether the limit can be set here (threadpoolctl importable)
AVAILABLE = ThreadpoolController is not None

_CONTROLLER = []  # the ThreadpoolController, made at the first use (it lists the loaded libraries)
_LOCK = threading.RLock()


@contextlib.contextmanager
def one_blas_thread():
    """The span with the process's BLAS at one thread (unchanged without threadpoolctl)."""
    if not AVAILABLE:
        yield
        return
    with _LOCK:  # (one span at a time: two threads' spans would restore each other's limits)
        with controller().limit(limits=1, user_api="blas"):
            yield


def controller():
    """The process's ThreadpoolController (None without threadpoolctl), made at the first call: it
    lists the loaded libraries (17 ms, which Live's first stroke paid: PreparedScene.prepare_live
    makes it before)."""
    if not AVAILABLE:
        return None
    with _LOCK:
        if not _CONTROLLER:
            _CONTROLLER.append(ThreadpoolController())
        return _CONTROLLER[0]
