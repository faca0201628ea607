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
