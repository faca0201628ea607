"""engine.blas_threads: Live's re-solves run with one BLAS thread, and the limit is given back."""
import threading

import numpy as np
import pytest

from relight_addon.engine import blas_threads

threadpoolctl = pytest.importorskip("threadpoolctl", reason="threadpoolctl is not installed (requirements.txt pins it)")


def blas_threads_now():
    """{library file: threads} of the BLAS libraries loaded in this process, as threadpoolctl reads them."""
    return {i["filepath"]: i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"}


def test_one_thread_inside_and_given_back():
    import scipy.linalg  # noqa: F401  (scipy's BLAS loaded too)

    before = blas_threads_now()
    assert before, "no BLAS library found: numpy and scipy load one"
    with blas_threads.one_blas_thread():
        assert set(blas_threads_now().values()) == {1}
        a = np.random.default_rng(0).standard_normal((300, 300))
        assert np.allclose(np.linalg.solve(a, a @ np.ones(300)), 1.0)  # (BLAS still works)
        with blas_threads.one_blas_thread():  # nested (the Live worker's finish inside a re-solve)
            assert set(blas_threads_now().values()) == {1}
        assert set(blas_threads_now().values()) == {1}
    assert blas_threads_now() == before


def test_given_back_after_an_error_and_across_threads():
    before = blas_threads_now()
    with pytest.raises(RuntimeError):
        with blas_threads.one_blas_thread():
            raise RuntimeError("a cancelled re-solve")
    assert blas_threads_now() == before
    seen = []

    def worker():
        with blas_threads.one_blas_thread():
            seen.append(set(blas_threads_now().values()))

    threads = [threading.Thread(target=worker) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert seen == [{1}] * 3
    assert blas_threads_now() == before


def test_the_controller_is_made_once_and_before_a_stroke(monkeypatch):
    """The ThreadpoolController lists the loaded libraries (17 ms, which Live's first stroke paid
    in its one_blas_thread): made once, shared by every span, and made by PreparedScene.prepare_live
    (before the first stroke: the worker's prewarm)."""
    made = []
    real = blas_threads.ThreadpoolController
    monkeypatch.setattr(blas_threads, "ThreadpoolController", lambda: made.append(1) or real())
    monkeypatch.setattr(blas_threads, "_CONTROLLER", [])
    first = blas_threads.controller()
    with blas_threads.one_blas_thread():
        pass
    assert blas_threads.controller() is first and len(made) == 1
    from relight_addon.pipeline import prepared

    monkeypatch.setattr(blas_threads, "_CONTROLLER", [])

    class Problem:  # (what prepare_live reads of the model: nothing kept by retarget here)
        target_rows = type("Rows", (), {"targets": []})()

        def all_rows_transfer(self):
            return None

    state = prepared.PreparedScene.__new__(prepared.PreparedScene)
    state.model = type("Model", (), {"problem": Problem()})()
    monkeypatch.setattr(prepared.PreparedScene, "_clustered_faces", lambda self: None)
    monkeypatch.setattr(prepared, "face_areas", lambda faces: None)
    state.prepare_live(None)
    assert len(blas_threads._CONTROLLER) == 1 and len(made) == 2
