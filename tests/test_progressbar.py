"""Progress callbacks (python/lmrefine/progressbar.py): the one rule for what
a callback's answer means, and that the native calls and the Python code
that reads an answer itself follow it alike."""

import numpy as np
import pytest

import lmrefine
from lmrefine.progressbar import cancels
from lmrefine.tessellation import tessellate

# (answer, cancels): None goes on (a plain print callback), any other false value stops.
ANSWERS = [(True, False), (1, False), ("yes", False), ([0], False), (None, False),
           (False, True), (0, True), (0.0, True), ("", True), ([], True)]


@pytest.mark.parametrize("answer, expected", ANSWERS)
def test_cancels_on_any_false_value_but_none(answer, expected):
    assert cancels(answer) is expected


@pytest.mark.parametrize("answer, expected", ANSWERS)
def test_native_calls_read_an_answer_the_same_way(answer, expected):
    image = np.zeros((16, 16), np.float32)
    if expected:
        with pytest.raises(lmrefine.CancelledError):
            lmrefine.gradient_map(image, progress=lambda fraction, stage: answer)
    else:
        lmrefine.gradient_map(image, progress=lambda fraction, stage: answer)


@pytest.mark.parametrize("answer, expected", ANSWERS)
def test_tessellation_reads_an_answer_the_same_way(answer, expected):
    # One triangle across a strong transition: tessellate asks for progress before it splits.
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    triangles = np.array([[0, 1, 2]])
    uvs = np.array([[0.05, 0.05], [0.95, 0.05], [0.05, 0.95]])
    strength = np.zeros((32, 32))
    strength[:, 8:10] = 1.0
    calls = []

    def progress(fraction, stage):
        calls.append(stage)
        return answer

    if expected:
        with pytest.raises(lmrefine.CancelledError):
            tessellate(positions, triangles, uvs, strength, budget=4.0, progress=progress)
        assert calls == ["tessellate"]
    else:
        result = tessellate(positions, triangles, uvs, strength, budget=4.0, progress=progress)
        assert calls and result.report["vertices_added"] > 0
