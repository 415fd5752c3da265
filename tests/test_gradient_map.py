import numpy as np
import pytest

import lmrefine

R, G, B, A = 0, 1, 2, 3  # r/b: along y (down, up); g/a: along x (right, left)
WAVELETS = ["haar", "d4", "d12", "d20", "cdf53", "cdf97"]


def f32(a):
    return np.ascontiguousarray(a, dtype=np.float32)


def nonzero_columns(channel):
    return sorted(set(np.nonzero(channel)[1].tolist()))


def test_hard_shadow_edge_lights_only_its_texels_and_direction():
    image = np.full((20, 32), 0.05, np.float32)
    image[:, :12] = 3.0  # lit left part; the edge lies between columns 11 and 12
    out = lmrefine.gradient_map(image)
    assert out.shape == (20, 32, 4) and out.dtype == np.float32
    # D4 (4 taps, centre 2): forward reads x[i-2..i+1], backward x[i-1..i+2].
    assert nonzero_columns(out[..., G]) == [11, 12, 13]
    assert nonzero_columns(out[..., A]) == [10, 11, 12]
    assert np.all(out[..., G][:, 11:14] > 0.1) and np.all(out[..., A][:, 10:13] > 0.1)
    assert np.all(out[..., [R, B]] == 0)  # no light change along y at all
    # The same edge turned by 90 degrees lands in r and b.
    out_t = lmrefine.gradient_map(f32(image.T))
    np.testing.assert_array_equal(out_t[..., R], out[..., G].T)
    np.testing.assert_array_equal(out_t[..., B], out[..., A].T)
    assert np.all(out_t[..., [G, A]] == 0)


@pytest.mark.parametrize("wavelet", WAVELETS)
def test_every_wavelet_localizes_an_edge_within_its_stencil(wavelet):
    image = np.zeros((6, 64), np.float32)
    image[:, 30:] = 1.0
    out = lmrefine.gradient_map(image, wavelet=wavelet)
    length = {"haar": 2, "d4": 4, "d12": 12, "d20": 20, "cdf53": 5, "cdf97": 9}[wavelet]
    cols = nonzero_columns(out[..., G]) + nonzero_columns(out[..., A])
    assert cols and min(cols) >= 30 - length and max(cols) <= 29 + length
    assert np.all(out[..., [R, B]] == 0)


@pytest.mark.parametrize("wavelet", WAVELETS)
def test_flat_light_is_exactly_zero_even_hdr(wavelet):
    image = np.full((9, 13), 1234.567, np.float32)
    mask = np.ones((9, 13), bool)
    mask[3:6, 4:9] = False
    assert not lmrefine.gradient_map(image, mask, wavelet=wavelet).any()


@pytest.mark.parametrize("wavelet", ["d4", "d12", "d20", "cdf53", "cdf97"])
def test_linear_ramp_gives_no_false_edge_at_image_or_mask_borders(wavelet):
    # Two vanishing moments (D4) and the point-symmetric extension of each
    # run of covered texels: a ramp continues exactly past every border.
    y, x = np.mgrid[0:40, 0:48].astype(np.float64)
    image = f32(2.0 + 0.05 * x - 0.03 * y)
    mask = np.ones((40, 48), bool)
    mask[10:20, 5:30] = False   # a hole
    mask[:, 40] = False         # a gutter column
    mask[33, :] = False         # a gutter row
    mask[25, 10] = False        # a lone uncovered texel
    out = lmrefine.gradient_map(image, mask, wavelet=wavelet)
    assert np.abs(out).max() < 2e-5  # float32 round-off of values around 2
    # The same mask and filter do see a light step of one tenth of the ramp's range.
    edge = lmrefine.gradient_map(f32(image + 0.2 * (x >= 24)), mask, wavelet=wavelet)
    assert np.abs(edge).max() > 0.02


def test_one_texel_shift_shifts_the_map_and_changes_nothing_else(rng):
    image = f32(rng.random((40, 50)) * 4)
    out = lmrefine.gradient_map(image)
    shifted_x = lmrefine.gradient_map(f32(np.roll(image, 1, axis=1)))
    shifted_y = lmrefine.gradient_map(f32(np.roll(image, 1, axis=0)))
    # Away from the image border (which is a border, not a wrap), bit for bit.
    np.testing.assert_array_equal(shifted_x[:, 4:-4], np.roll(out, 1, axis=1)[:, 4:-4])
    np.testing.assert_array_equal(shifted_y[4:-4], np.roll(out, 1, axis=0)[4:-4])


def test_shift_with_mask_shifts_too(rng):
    image = f32(rng.random((30, 30)))
    mask = np.zeros((30, 30), bool)
    mask[5:20, 3:17] = True
    mask[22:27, 8:25] = True
    out = lmrefine.gradient_map(image, mask)
    moved = lmrefine.gradient_map(f32(np.roll(image, 1, axis=1)), np.roll(mask, 1, axis=1))
    np.testing.assert_array_equal(moved, np.roll(out, 1, axis=1))


def test_d4_channel_is_the_modified_predict_of_the_lifting(rng):
    x = f32(rng.standard_normal(64))
    out = lmrefine.gradient_map(x[None, :])
    approx, detail = lmrefine.dwt(x, "d4", "periodic")
    # The lifting detail d[n] reads x[2n-2 .. 2n+1]; the forward channel at
    # texel i reads x[i-2 .. i+1]; so g at 2n is |d[n]| (inside the signal).
    np.testing.assert_allclose(out[0, 2:63:2, G], np.abs(detail[1:]), atol=1e-5)
    # The backward channel is the same filter on the reversed line.
    back = lmrefine.gradient_map(f32(x[::-1])[None, :])
    np.testing.assert_allclose(out[0, 3:-3, A], back[0, ::-1][3:-3, G], atol=1e-6)


@pytest.mark.parametrize("garbage", [1e30, -np.inf, np.nan, 0.0])
def test_nothing_leaks_across_a_mask_border(rng, garbage):
    image = f32(rng.random((32, 32)))
    mask = np.zeros((32, 32), bool)
    mask[2:14, 3:20] = True
    mask[16:30, 10:31] = True
    mask[18:22, 14:18] = False
    out = lmrefine.gradient_map(image, mask)
    dirty = image.copy()
    dirty[~mask] = garbage
    out_dirty = lmrefine.gradient_map(dirty, mask)
    np.testing.assert_array_equal(out_dirty, out)  # bit for bit
    assert not out[~mask].any()
    assert out[mask].any()


def test_rgb_is_rec709_luminance_and_alpha_is_ignored(rng):
    rgb = f32(rng.random((12, 20, 3)) * 5)
    lum = f32(0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2])
    expected = lmrefine.gradient_map(lum)
    np.testing.assert_allclose(lmrefine.gradient_map(rgb), expected, rtol=1e-5, atol=1e-5)
    rgba = f32(np.concatenate([rgb, rng.random((12, 20, 1))], axis=2))
    rgba[3, 4, 3] = np.nan  # alpha is never read
    np.testing.assert_array_equal(lmrefine.gradient_map(rgba), lmrefine.gradient_map(rgb))
    np.testing.assert_array_equal(lmrefine.gradient_map(lum[..., None]), expected)


def test_odd_and_tiny_sizes():
    assert not lmrefine.gradient_map(np.ones((1, 1), np.float32)).any()
    single_row = lmrefine.gradient_map(f32([[0, 0, 0, 1, 1]]))
    assert single_row.shape == (1, 5, 4) and single_row[..., G].any() and not single_row[..., R].any()
    ramp = f32(np.arange(21).reshape(3, 7) * 0.5)
    assert np.abs(lmrefine.gradient_map(ramp)).max() < 1e-5
    two = f32([[0.0, 1.0]])  # a run of two texels is a ramp: nothing to see
    assert np.abs(lmrefine.gradient_map(two)).max() < 1e-6


def test_input_is_not_modified(rng):
    image = f32(rng.random((8, 9, 4)))
    copy = image.copy()
    lmrefine.gradient_map(image, np.ones((8, 9), bool))
    np.testing.assert_array_equal(image, copy)


@pytest.mark.parametrize("image,mask,kwargs,match", [
    (np.zeros((4, 4), np.float64), None, {}, "float32"),
    (np.zeros(4, np.float32), None, {}, "dimensions"),
    (np.zeros((2, 2, 2, 2), np.float32), None, {}, "dimensions"),
    (np.zeros((4, 4, 2), np.float32), None, {}, r"\(H, W, 3\)"),
    (np.zeros((0, 4), np.float32), None, {}, "empty"),
    (np.zeros((4, 4), np.float32), np.ones((4, 5), bool), {}, "shape"),
    (np.zeros((4, 4), np.float32), np.ones((4, 4), np.uint8), {}, "bool"),
    (np.zeros((4, 4), np.float32), np.zeros((4, 4), bool), {}, r"coverage_mask\(uvs, triangles, resolution\)"),
    (np.zeros((4, 4), np.float32), None, {"wavelet": "d6"}, "valid names"),
])
def test_bad_input(image, mask, kwargs, match):
    with pytest.raises(ValueError, match=match):
        lmrefine.gradient_map(image, mask, **kwargs)


def test_non_finite_covered_texels_are_named():
    image = np.zeros((6, 8), np.float32)
    image[3, 4] = np.nan
    image[5, 1] = np.inf
    image[0, 0] = np.nan  # uncovered: fine
    mask = np.ones((6, 8), bool)
    mask[0, 0] = False
    with pytest.raises(ValueError, match=r"2 non-finite .* row 3, column 4"):
        lmrefine.gradient_map(image, mask)


def test_progress_and_cancel():
    image = np.zeros((64, 64), np.float32)
    seen = []
    lmrefine.gradient_map(image, progress=lambda fraction, stage: seen.append(fraction) or True)
    assert seen and seen[-1] == pytest.approx(1.0)
    with pytest.raises(lmrefine.CancelledError):
        lmrefine.gradient_map(image, progress=lambda fraction, stage: False)


# --- An independent reference: the documented rule, written out in numpy ---------

def detail_taps(wavelet):
    """The detail filter from impulse responses of lmrefine.dwt (1-D lifting)."""
    taps = []
    for i in range(32):
        x = np.zeros(32, np.float32)
        x[i] = 1.0
        taps.append(lmrefine.dwt(x, wavelet, "periodic")[1][8])
    taps = np.array(taps, np.float64)
    nz = np.nonzero(np.abs(taps) > 1e-7)[0]
    return taps[nz[0]:nz[-1] + 1]


def antireflect(run, j):
    n = len(run)
    if n == 1:
        return run[0]
    if j < 0:
        return 2 * run[0] - antireflect(run, -j)
    if j >= n:
        return 2 * run[-1] - antireflect(run, 2 * (n - 1) - j)
    return run[j]


def reference_rows(lum, mask, taps):
    """|forward| and |backward| detail along each row, run by run."""
    length, c = len(taps), len(taps) // 2
    fwd, bwd = np.zeros_like(lum, np.float64), np.zeros_like(lum, np.float64)
    for r in range(lum.shape[0]):
        j = 0
        while j < lum.shape[1]:
            if not mask[r, j]:
                j += 1
                continue
            end = j
            while end < lum.shape[1] and mask[r, end]:
                end += 1
            run = lum[r, j:end].astype(np.float64)
            for t in range(len(run)):
                fwd[r, j + t] = abs(sum(taps[k] * antireflect(run, t - c + k) for k in range(length)))
                bwd[r, j + t] = abs(sum(taps[k] * antireflect(run, t + c - k) for k in range(length)))
            j = end
    return fwd, bwd


@pytest.mark.parametrize("wavelet", ["d4", "d12", "cdf97"])
def test_matches_a_plain_reference_of_the_documented_rule(rng, wavelet):
    image = f32(rng.random((17, 23)) * 3)
    mask = rng.random((17, 23)) > 0.15
    mask[4:9, 6:15] = False
    taps = detail_taps(wavelet)
    g, a = reference_rows(image, mask, taps)
    r, b = (m.T for m in reference_rows(image.T, mask.T, taps))
    expected = np.stack([r, g, b, a], axis=-1)
    np.testing.assert_allclose(lmrefine.gradient_map(image, mask, wavelet=wavelet), expected, atol=2e-5)


def test_no_mask_means_everything_covered(rng):
    image = f32(rng.random((9, 11)))
    np.testing.assert_array_equal(lmrefine.gradient_map(image), lmrefine.gradient_map(image, np.ones((9, 11), bool)))
