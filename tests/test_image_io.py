import numpy as np
import pytest

import lmrefine


@pytest.mark.parametrize("ext,kwargs,tol", [
    (".exr", {}, 0.0),
    (".exr", {"format": "half"}, 1e-3),
    (".tif", {}, 0.0),
    (".png", {}, 2.3 * 0.5 / 255),  # half an 8-bit step times the sRGB decode slope near 1
    (".png", {"format": "uint16"}, 1e-4),
])
def test_round_trip_rgba(tmp_path, rng, ext, kwargs, tol):
    image = rng.random((6, 9, 4), dtype=np.float32)
    path = tmp_path / f"img{ext}"
    lmrefine.write_image(path, image, **kwargs)
    back = lmrefine.read_image(path)
    assert back.dtype == np.float32 and back.shape == (6, 9, 4)
    assert np.abs(back - image).max() <= tol * max(1.0, np.abs(image).max())


def test_hdr_round_trip_keeps_rgbe_precision(tmp_path, rng):
    image = (rng.random((4, 5, 3), dtype=np.float32) * 50.0).astype(np.float32)
    lmrefine.write_image(tmp_path / "a.hdr", image)
    back = lmrefine.read_image(tmp_path / "a.hdr")
    # RGBE keeps 8 bits of mantissa for the largest channel of a texel.
    assert np.allclose(back, image, rtol=2e-2, atol=image.max() / 128)


def test_row_zero_is_the_top_of_the_file(tmp_path):
    image = np.zeros((4, 4), np.float32)
    image[0, :] = 1.0  # top row bright
    lmrefine.write_image(tmp_path / "top.exr", image)
    back = lmrefine.read_image(tmp_path / "top.exr")
    assert back.shape == (4, 4, 1)
    assert back[0, :, 0].min() == 1.0 and back[1:, :, 0].max() == 0.0


def test_single_channel_hdr_becomes_gray_rgb(tmp_path):
    image = np.full((3, 3), 2.5, np.float32)
    lmrefine.write_image(tmp_path / "g.hdr", image)
    back = lmrefine.read_image(tmp_path / "g.hdr")
    assert back.shape == (3, 3, 3) and np.allclose(back, 2.5, rtol=1e-2)


def test_missing_file_names_the_file(tmp_path):
    with pytest.raises(OSError, match="nothing_here.exr"):
        lmrefine.read_image(tmp_path / "nothing_here.exr")


def test_unwritable_folder_names_the_file(tmp_path):
    with pytest.raises(OSError, match="no_such_dir"):
        lmrefine.write_image(tmp_path / "no_such_dir" / "x.exr", np.zeros((2, 2), np.float32))


@pytest.mark.parametrize("name,array,kwargs,match", [
    ("x.exr", np.zeros((2, 2), np.float64), {}, "float32"),
    ("x.exr", np.zeros((2,), np.float32), {}, "dimensions"),
    ("x.exr", np.zeros((0, 2), np.float32), {}, "empty"),
    ("x.exr", np.zeros((2, 2, 5), np.float32), {}, "channels"),
    ("x.bmpx", np.zeros((2, 2), np.float32), {}, "extension"),
    ("x.hdr", np.zeros((2, 2, 4), np.float32), {}, "alpha"),
    ("x.png", np.zeros((2, 2), np.float32), {"format": "float"}, "16 bits"),
    ("x.png", np.full((2, 2), np.nan, np.float32), {}, "NaN"),
    ("x.exr", np.zeros((2, 2), np.float32), {"format": "int4"}, "format"),
])
def test_bad_writes_raise_value_error_and_leave_no_file(tmp_path, name, array, kwargs, match):
    with pytest.raises(ValueError, match=match):
        lmrefine.write_image(tmp_path / name, array, **kwargs)
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_the_existing_file(tmp_path):
    path = tmp_path / "keep.png"
    original = np.full((2, 2), 0.5, np.float32)
    lmrefine.write_image(path, original)
    before = path.read_bytes()
    with pytest.raises(ValueError):
        lmrefine.write_image(path, np.full((2, 2), np.inf, np.float32))
    assert path.read_bytes() == before
