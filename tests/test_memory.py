"""brdf.memory: the pool of result blocks behind ``Model.eval``'s fresh outputs."""

import numpy as np
import pytest

import brdf
from brdf import memory

BIG = (memory.POOL_MIN // 24 + 1000, 3)  # float64 rows just over the pool's threshold


@pytest.fixture(autouse=True)
def empty_pool():
    memory.trim()
    yield
    memory.trim()


def test_a_pooled_array_is_an_aligned_writable_c_array_of_the_shape_asked():
    a = memory.empty(BIG)
    assert a.shape == BIG and a.dtype == np.float64
    assert a.flags.c_contiguous and a.flags.writeable
    assert a.ctypes.data % 64 == 0
    a[...] = 1.5
    assert a.sum() == 1.5 * a.size
    b = memory.empty(BIG[0] * 3, np.float32)
    assert b.shape == (BIG[0] * 3,) and b.dtype == np.float32


def test_small_requests_are_plain_numpy_arrays():
    a = memory.empty((16, 3))
    assert a.base is None and a.flags.owndata
    del a
    assert memory.trim() == 0


def test_a_block_comes_back_only_when_the_array_and_its_views_are_gone():
    a = memory.empty(BIG)
    where = a.ctypes.data
    view = a[5:]
    del a
    assert memory.trim() == 0  # the view still holds the block
    other = memory.empty(BIG)
    assert not np.shares_memory(other, view)
    del view
    again = memory.empty(BIG)
    assert again.ctypes.data == where  # the block the view let go
    assert not np.shares_memory(again, other)


def test_close_sizes_share_blocks_and_far_ones_do_not():
    a = memory.empty(BIG)
    where = a.ctypes.data
    del a
    assert memory.empty((BIG[0] - 7, 3)).ctypes.data == where  # the same 2 MiB grain
    far = memory.empty((BIG[0] * 4, 3))
    assert far.ctypes.data != where
    del far
    assert memory.trim() >= 2 * BIG[0] * 3 * 8


def test_the_pool_holds_at_most_pool_bytes(monkeypatch):
    monkeypatch.setattr(memory, "POOL_BYTES", 3 * memory.POOL_MIN)
    arrays = [memory.empty(BIG) for _ in range(6)]
    del arrays
    held = memory.trim()
    assert 0 < held <= 3 * memory.POOL_MIN


def test_a_drop_while_the_pool_is_locked_frees_the_block_without_waiting():
    a = memory.empty(BIG)
    with memory._lock:  # as a collection running inside the pool's own critical section
        del a  # the lease cannot take the lock: its block goes to the system, nothing waits
    assert memory.trim() == 0


def test_results_of_successive_evaluations_never_share_memory():
    model = brdf.models.Lambert(albedo=(0.5, 0.4, 0.3)) + brdf.models.GGX(alpha=0.3)
    rng = np.random.default_rng(7)
    n = BIG[0]
    wi, wo = (brdf.geometry.normalize(rng.normal(size=(n, 3)) * [1, 1, 0] + [0, 0, 1.2])
              for _ in range(2))
    first = model.eval(wi, wo)
    kept = first.copy()
    second = model.eval(wo, wi)  # reciprocal: the same values, in another array
    assert not np.shares_memory(first, second)
    np.testing.assert_array_equal(first, kept)
    np.testing.assert_allclose(second, first, rtol=1e-12)
    where = first.ctypes.data
    del first
    third = model.eval(wi, wo)  # takes the block the first result gave back
    assert third.ctypes.data == where
    np.testing.assert_array_equal(third, kept)
    pdf = model.pdf(wi, wo)
    assert pdf.shape == (n,)
