import numpy as np
import pytest
import pywt

import lmrefine

WAVELETS = ["haar", "d4", "d12", "d20", "cdf53", "cdf97"]
MODES = ["periodic", "symmetric"]


def f32(a):
    return np.ascontiguousarray(a, dtype=np.float32)


def pywt_dwt(x, name):
    return pywt.dwt(x.astype(np.float64), name, mode="periodization")


# --- Relation to PyWavelets (mode='periodization') ----------------------------

@pytest.mark.parametrize("length", [8, 30, 64, 250])
def test_d4_is_pywt_db2_of_the_signal_advanced_by_one_sample(rng, length):
    x = f32(rng.standard_normal(length))
    approx, detail = lmrefine.dwt(x, "d4", "periodic")
    a, d = pywt_dwt(np.roll(x, -1), "db2")  # x'[t] = x[t + 1]
    np.testing.assert_allclose(approx, a, atol=1e-5)
    np.testing.assert_allclose(detail, -np.roll(d, 1), atol=1e-5)  # d[n] = -d'[n - 1]


def test_d4_lowpass_is_the_method_filter(rng):
    x = f32(rng.standard_normal(16))
    s3 = np.sqrt(3.0)
    h = np.array([1 + s3, 3 + s3, 3 - s3, 1 - s3]) / (4 * np.sqrt(2))
    expected = [sum(h[k] * x[(2 * n + k) % 16] for k in range(4)) for n in range(8)]
    np.testing.assert_allclose(lmrefine.dwt(x, "d4")[0], expected, atol=1e-5)


def test_d4_2d_is_pywt_dwt2_db2_up_to_the_same_shift_and_sign(rng):
    image = f32(rng.standard_normal((24, 40)))
    ll, lh, hl, hh = lmrefine.dwt2(image, "d4", "periodic")
    ca, (ch, cv, cd) = pywt.dwt2(np.roll(image, (-1, -1), axis=(0, 1)).astype(np.float64), "db2",
                                 mode="periodization")
    np.testing.assert_allclose(ll, ca, atol=1e-5)
    np.testing.assert_allclose(lh, -np.roll(ch, 1, axis=0), atol=1e-5)  # high along y = cH
    np.testing.assert_allclose(hl, -np.roll(cv, 1, axis=1), atol=1e-5)  # high along x = cV
    np.testing.assert_allclose(hh, np.roll(cd, (1, 1), axis=(0, 1)), atol=1e-5)


@pytest.mark.parametrize("name,pywt_name,approx_roll,detail_roll", [
    ("d12", "db6", -1, 2),
    ("d20", "db10", -4, 5),
])
def test_long_daubechies_match_pywt(rng, name, pywt_name, approx_roll, detail_roll):
    x = f32(rng.standard_normal(96))
    approx, detail = lmrefine.dwt(x, name, "periodic")
    a, d = pywt_dwt(np.roll(x, -1), pywt_name)
    np.testing.assert_allclose(approx, np.roll(a, approx_roll), atol=2e-5)
    np.testing.assert_allclose(detail, np.roll(d, detail_roll), atol=2e-5)


@pytest.mark.parametrize("name,pywt_name", [("haar", "haar"), ("cdf53", "bior2.2"), ("cdf97", "bior4.4")])
def test_haar_and_cdf_equal_pywt_exactly(rng, name, pywt_name):
    x = f32(rng.standard_normal(50))
    approx, detail = lmrefine.dwt(x, name, "periodic")
    a, d = pywt_dwt(x, pywt_name)
    np.testing.assert_allclose(approx, a, atol=1e-5)
    np.testing.assert_allclose(detail, d, atol=1e-5)


@pytest.mark.parametrize("name", ["cdf53", "cdf97"])
def test_symmetric_mode_is_the_whole_sample_mirror_of_the_signal(rng, name):
    # For the symmetric CDF filters, per-step mirroring equals transforming
    # the signal mirrored about its end samples (period 2N - 2).
    x = f32(rng.standard_normal(20))
    mirrored = f32(np.concatenate([x, x[-2:0:-1]]))
    approx, detail = lmrefine.dwt(x, name, "symmetric")
    a, d = lmrefine.dwt(mirrored, name, "periodic")
    np.testing.assert_allclose(approx, a[:10], atol=1e-5)
    np.testing.assert_allclose(detail, d[:10], atol=1e-5)


def test_modes_differ_only_near_the_boundary(rng):
    x = f32(rng.standard_normal(64))
    ap, dp = lmrefine.dwt(x, "d4", "periodic")
    as_, ds = lmrefine.dwt(x, "d4", "symmetric")
    assert not np.allclose(ap, as_)
    np.testing.assert_array_equal(ap[2:-2], as_[2:-2])
    np.testing.assert_array_equal(dp[2:-2], ds[2:-2])


def test_lh_holds_light_changing_along_y():
    image = np.zeros((16, 16), np.float32)
    image[5:, :] = 1.0  # a horizontal edge: light changes along y
    ll, lh, hl, hh = lmrefine.dwt2(image, "d4", "symmetric")
    assert np.abs(lh).max() > 0.3
    assert np.abs(hl).max() < 1e-6 and np.abs(hh).max() < 1e-6
    ll, lh, hl, hh = lmrefine.dwt2(np.ascontiguousarray(image.T), "d4", "symmetric")
    assert np.abs(hl).max() > 0.3 and np.abs(lh).max() < 1e-6


# --- Perfect reconstruction ---------------------------------------------------

@pytest.mark.parametrize("wavelet", WAVELETS)
@pytest.mark.parametrize("mode", MODES)
def test_perfect_reconstruction_1d(rng, wavelet, mode):
    for length in (2, 4, 6, 10, 38, 256):
        x = f32(rng.standard_normal(length) * 10 + 3)
        y = lmrefine.idwt(lmrefine.dwt(x, wavelet, mode), wavelet, mode)
        assert y.shape == x.shape and y.dtype == np.float32
        assert np.abs(y - x).max() <= 1e-5 * np.abs(x).max()


@pytest.mark.parametrize("wavelet", WAVELETS)
@pytest.mark.parametrize("mode", MODES)
def test_perfect_reconstruction_2d(rng, wavelet, mode):
    for shape in ((2, 2), (4, 6), (16, 10), (34, 18), (130, 72)):
        image = f32(rng.random(shape) * 100)
        bands = lmrefine.dwt2(image, wavelet, mode)
        assert all(b.shape == (shape[0] // 2, shape[1] // 2) and b.dtype == np.float32 for b in bands)
        copies = [b.copy() for b in bands]
        back = lmrefine.idwt2(bands, wavelet, mode)
        assert back.shape == shape
        assert np.abs(back - image).max() <= 1e-5 * np.abs(image).max()
        for b, c in zip(bands, copies):
            np.testing.assert_array_equal(b, c)  # idwt2 leaves its input alone


def test_orthogonal_wavelets_keep_energy(rng):
    image = f32(rng.standard_normal((32, 32)))
    for wavelet in ("haar", "d4", "d12", "d20"):
        energy = sum(float(np.sum(b.astype(np.float64) ** 2)) for b in lmrefine.dwt2(image, wavelet))
        assert energy == pytest.approx(float(np.sum(image.astype(np.float64) ** 2)), rel=1e-5)


def test_dwt2_does_not_modify_its_input(rng):
    image = f32(rng.random((8, 8)))
    copy = image.copy()
    lmrefine.dwt2(image, "cdf97", "symmetric")
    np.testing.assert_array_equal(image, copy)


# --- Bad input ------------------------------------------------------------------

@pytest.mark.parametrize("image,kwargs,match", [
    (np.zeros((5, 4), np.float32), {}, "even"),
    (np.zeros((4, 3), np.float32), {}, "even"),
    (np.zeros((1, 4), np.float32), {}, "even"),
    (np.zeros((4, 4), np.float64), {}, "float32"),
    (np.zeros(4, np.float32), {}, "dimensions"),
    (np.zeros((4, 4, 3), np.float32), {}, "dimensions"),
    (np.zeros((0, 4), np.float32), {}, "empty"),
    ([[0.0, 1.0], [1.0, 0.0]], {}, "numpy array"),
    (np.zeros((4, 4), np.float32), {"wavelet": "db2"}, "valid names: 'haar', 'd4', 'd12', 'd20', 'cdf53', 'cdf97'"),
    (np.zeros((4, 4), np.float32), {"mode": "zero"}, "'periodic', 'symmetric'"),
])
def test_dwt2_bad_input(image, kwargs, match):
    with pytest.raises(ValueError, match=match):
        lmrefine.dwt2(image, **kwargs)


def test_idwt2_bad_input():
    band = np.zeros((2, 3), np.float32)
    with pytest.raises(ValueError, match="one shape"):
        lmrefine.idwt2((band, band, band, np.zeros((2, 2), np.float32)))
    with pytest.raises(ValueError, match="tuple"):
        lmrefine.idwt2((band, band, band))
    with pytest.raises(ValueError, match="float32"):
        lmrefine.idwt2((band, band, band, band.astype(np.float64)))


def test_dwt_bad_input():
    with pytest.raises(ValueError, match="even"):
        lmrefine.dwt(np.zeros(7, np.float32))
    with pytest.raises(ValueError, match="dimensions"):
        lmrefine.dwt(np.zeros((2, 2), np.float32))
    with pytest.raises(ValueError, match="one shape"):
        lmrefine.idwt((np.zeros(3, np.float32), np.zeros(4, np.float32)))


def test_dwt2_progress_and_cancel():
    image = np.zeros((64, 64), np.float32)
    seen = []
    lmrefine.dwt2(image, progress=lambda fraction, stage: seen.append((fraction, stage)) or True)
    assert seen and seen[-1][0] == pytest.approx(1.0) and seen[0][1] == "wavelet transform"
    with pytest.raises(lmrefine.CancelledError):
        lmrefine.dwt2(image, progress=lambda fraction, stage: False)
