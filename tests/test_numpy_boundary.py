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
