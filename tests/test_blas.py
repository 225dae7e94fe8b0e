"""tracer.blas.one_blas_thread: OpenBLAS on one thread inside the block, the caller's setting after it."""
import pytest

from tracer.blas import _openblas, one_blas_thread


def test_one_thread_inside_and_the_old_count_after():
    functions = _openblas()
    if functions is None:
        pytest.skip("NumPy is not linked with OpenBLAS here")
    setter, getter = functions
    before = getter()
    setter(2)
    try:
        with one_blas_thread():
            assert getter() == 1
        assert getter() == 2
        with pytest.raises(RuntimeError):
            with one_blas_thread():
                raise RuntimeError("the setting comes back on errors too")
        assert getter() == 2
    finally:
        setter(before)
