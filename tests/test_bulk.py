"""tracer.bulk: OpenBLAS on one thread and the collector paused inside a block, the caller's settings after it."""
import pytest

from tracer.bulk import _openblas, one_blas_thread


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


def test_collector_paused_inside_and_restored_after():
    import gc

    from tracer.bulk import collector_paused
    assert gc.isenabled()
    with collector_paused():
        assert not gc.isenabled()
    assert gc.isenabled()
    gc.disable()
    try:
        with collector_paused():
            pass
        assert not gc.isenabled()  # a caller's own choice is kept
    finally:
        gc.enable()
