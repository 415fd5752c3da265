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
