"""Arrays crossing into the extension (native/bindings/numpy_util.cpp):
dtypes are compared by equality, not identity."""

import pickle

import numpy as np
import pytest

import lmrefine


def test_arrays_from_another_process_are_accepted():
    # multiprocessing pickles arrays: their dtype objects are equal to, but
    # not the same object as, numpy's float32 / bool / int32.
    rng = np.random.default_rng(7)
    energy, mask = (rng.random((40, 30)) ** 3).astype(np.float32), rng.random((40, 30)) < 0.9
    lightmap = pickle.loads(pickle.dumps(energy[..., None].repeat(3, axis=2)))
    pickled_mask = pickle.loads(pickle.dumps(mask))
    assert lightmap.dtype is not np.dtype(np.float32)
    np.testing.assert_array_equal(lmrefine.gradient_map(lightmap, pickled_mask),
                                  lmrefine.gradient_map(np.ascontiguousarray(lightmap), mask))
    np.testing.assert_array_equal(lmrefine.run_automaton(pickle.loads(pickle.dumps(energy)), mask)["grid"],
                                  lmrefine.run_automaton(energy, mask)["grid"])
    with pytest.raises(ValueError, match="float32"):
        lmrefine.gradient_map(energy.astype(">f4"), mask)


def test_an_unaligned_array_is_copied_before_a_kernel_reads_it():
    # A view at an odd byte offset is C-contiguous but not aligned for float32: read in place it is
    # undefined behaviour (UBSan's misaligned load); the kernel gets an aligned copy, the same values.
    rng = np.random.default_rng(0)
    lightmap = rng.random((32, 32, 3), dtype=np.float32)
    raw = np.zeros(lightmap.nbytes + 1, np.uint8)
    raw[1:] = lightmap.view(np.uint8).ravel()
    unaligned = np.frombuffer(raw.data, np.float32, offset=1).reshape(lightmap.shape)
    assert not unaligned.flags.aligned and unaligned.flags.c_contiguous
    np.testing.assert_array_equal(lmrefine.gradient_map(unaligned), lmrefine.gradient_map(lightmap))


HUGE = np.uint64(2**64 - 1)


@pytest.mark.parametrize("dtype", [np.uint64, np.uint32, np.int64])
def test_an_index_past_int32_is_reported_as_given(dtype):
    # uint64's largest value was reported as index -1 (wrapped to int64 before the range check).
    uvs = np.array([[0, 0], [1, 0], [0, 1]], np.float32)
    big = HUGE if dtype == np.uint64 else np.iinfo(dtype).max
    triangles = np.array([[0, 1, 2], [0, 1, big]], dtype)
    with pytest.raises(ValueError) as raised:
        lmrefine.find_charts(uvs, triangles)
    assert str(raised.value) == f"triangles[1] holds index {big}, outside the int32 range of valid indices"
    # A view with strides: the value printed is the element refused.
    strided = np.array([[0, 1, 2, 7], [0, 1, big, 7]], dtype)[:, :3]
    with pytest.raises(ValueError, match=f"triangles\\[1\\] holds index {big},"):
        lmrefine.find_charts(uvs, strided)


def test_chart_ids_and_polygon_ids_past_int64_are_reported_as_given():
    uvs = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float32)
    triangles = np.array([[0, 1, 2], [1, 3, 2]], np.int32)
    with pytest.raises(ValueError, match=f"charts\\[1\\] is {HUGE}; chart ids must be in \\[0, 2\\)"):
        lmrefine.pack_charts(uvs, triangles, np.array([0, HUGE], np.uint64), None, 64)
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    # A wrapped -1 was taken as a valid polygon id.
    with pytest.raises(ValueError, match=f"polygons\\[1\\] is {HUGE}, outside the int32 range"):
        lmrefine.rechart(positions, triangles, 10.0, 64, polygons=np.array([0, HUGE], np.uint64))
