"""Error messages for users: no C++ source locations (python/lmrefine/messages.py)."""

import numpy as np
import pytest

import lmrefine
from lmrefine.messages import user_message, without_source_location


def test_a_native_error_loses_its_source_location_and_keeps_its_words():
    with pytest.raises(ValueError) as raised:
        lmrefine.coverage_mask(np.zeros((3, 2), np.float32), np.array([[0, 1, 7]]), 16)
    assert ".cpp:" in str(raised.value)  # the core says where, for bug reports
    shown = user_message(raised.value)
    assert ".cpp" not in shown
    assert shown == str(raised.value)[:str(raised.value).rindex(" [")]
    assert shown.startswith("triangles[0] refers to UV 7")


@pytest.mark.parametrize("text, expected", [
    ("bad uvs [numpy_util.cpp:88]", "bad uvs"),
    ("a [x.h:1]; b [dir/y.cpp:22] end", "a; b end"),
    ("no location [here]", "no location [here]"),
])
def test_without_source_location(text, expected):
    assert without_source_location(text) == expected


def test_other_errors_keep_their_type():
    assert user_message(RuntimeError("bake failed [baker.cpp:231]")) == "RuntimeError: bake failed"
    assert user_message(KeyError()) == "KeyError"
