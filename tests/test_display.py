"""Display rendering against values computed by hand: percentiles, colour maps, PCA, mosaics."""

import warnings

import numpy as np
import pytest

from plantreg_gui.core.display import display
from plantreg_gui.core.display.display import (
    AREA_COLOURS, BACKGROUND_RGB, CASE_COLOURS, auto_limits, blend, checkerboard, mosaic, overlay,
    pca_false_colour, pca_scores, to_rgb8,
)


def _ramp():
    """(11, 101) image whose every row is 0, 1, ..., 100 (percentile p is exactly p)."""
    return np.tile(np.arange(101, dtype=np.float32), (11, 1))


def test_auto_limits_are_the_percentiles_of_finite_pixels():
    img = _ramp()
    assert auto_limits(img, (1, 99)) == pytest.approx((1.0, 99.0))
    assert auto_limits(img, (10, 90)) == pytest.approx((10.0, 90.0))
    img[:, ::2] = np.nan  # leaves the odd values 1, 3, ..., 99
    assert auto_limits(img, (0, 100)) == pytest.approx((1.0, 99.0))
    mask = np.zeros(img.shape, bool)
    mask[:, 51:] = True  # statistics from the right half only
    assert auto_limits(img, (0, 100), mask=mask) == pytest.approx((51.0, 99.0))
    assert auto_limits(np.full((4, 4), np.nan, np.float32)) == (0.0, 1.0)
    lo, hi = auto_limits(np.full((4, 4), 7.0))
    assert lo == 7.0 and hi > lo


def test_grey_stretch_maps_percentiles_to_black_and_white():
    out = to_rgb8(_ramp(), modality="infrared", percentiles=(1, 99))
    assert out.shape == (11, 101, 3) and out.dtype == np.uint8
    grey = out[0, :, 0]
    assert np.all(out[..., 0] == out[..., 1]) and np.all(out[..., 1] == out[..., 2])
    assert grey[0] == 0 and grey[1] == 0 and grey[99] == 255 and grey[100] == 255
    # linear in between: value v -> (v - 1) * 255 / 98, rounded
    for v in (2, 25, 50, 75, 98):
        assert abs(int(grey[v]) - (v - 1) * 255 / 98) <= 0.5 + 1e-9
    # explicit limits override percentiles
    out = to_rgb8(_ramp(), modality="infrared", limits=(0, 100))
    assert out[0, 50, 0] in (127, 128) and out[0, 100, 0] == 255


def test_nan_pixels_are_background_and_do_not_move_the_limits():
    img = _ramp()
    ref = to_rgb8(img, modality="infrared")
    img[3, :] = np.nan
    img[5, 7] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = to_rgb8(img, modality="infrared")
        empty = to_rgb8(np.full((5, 6), np.nan, np.float32), modality="thermal")
    assert np.all(out[3] == BACKGROUND_RGB) and tuple(out[5, 7]) == BACKGROUND_RGB
    keep = np.isfinite(img)
    assert np.array_equal(out[keep], ref[keep])
    assert np.all(empty == BACKGROUND_RGB)


def test_thermal_default_is_diverging_blue_white_red():
    img = np.linspace(20.0, 30.0, 201, dtype=np.float32)[None, :]
    out = to_rgb8(img, modality="thermal", percentiles=(0, 100)).astype(int)
    cold, mid, hot = out[0, 0], out[0, 100], out[0, 200]
    assert cold[2] > cold[0] + 50                      # blue
    assert hot[0] > hot[2] + 50                        # red
    assert min(mid) > 200 and max(mid) - min(mid) < 20  # near white


def test_rgb_uint8_is_shown_as_it_is_and_16_bit_is_stretched_keeping_hue():
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    assert np.array_equal(to_rgb8(rgb, modality="rgb"), rgb)
    # uint16 with one set of limits for all channels: 0 -> 0, 65535 -> 255, hue ratio kept
    a = np.zeros((10, 10, 3), np.uint16)
    a[:5] = (65535, 0, 0)
    a[5:] = (40000, 20000, 0)
    out = to_rgb8(a, modality="rgb", percentiles=(0, 100)).astype(int)
    assert tuple(out[0, 0]) == (255, 0, 0)
    r, g, _ = out[9, 9]
    assert r == round(40000 / 65535 * 255) and abs(g - r / 2) <= 1


def _two_material_cube(nan_rows=0):
    """(40, 50, 30) cube: left half material A, right half material B, plus small noise.

    The spectra differ along a known direction d, the noise (0.01) is far below the contrast
    (norm 1 over 30 bands), so PC1 must be d and must separate the halves.
    """
    rng = np.random.default_rng(3)
    B = 30
    wl = np.linspace(0, 1, B)
    base = 0.3 + 0.2 * wl
    d = np.exp(-((wl - 0.7) / 0.1) ** 2)  # a red-edge-like bump
    d /= np.linalg.norm(d)
    cube = np.empty((40, 50, B), np.float32)
    cube[:, :25] = base + 0.5 * d
    cube[:, 25:] = base - 0.5 * d
    cube += rng.normal(0, 0.01, cube.shape).astype(np.float32)
    if nan_rows:
        cube[:nan_rows] = np.nan
    return cube, d


def test_pca_first_component_is_the_material_contrast():
    cube, d = _two_material_cube()
    s = pca_scores(cube)
    assert s.shape == (40, 50, 3) and s.dtype == np.float32
    pc1 = s[..., 0].ravel()
    proj = (cube.reshape(-1, cube.shape[2]) @ d).astype(np.float64)
    assert abs(np.corrcoef(pc1, proj)[0, 1]) > 0.999
    a, b = s[:, :25, 0], s[:, 25:, 0]
    assert min(a.min(), b.min()) < 0 < max(a.max(), b.max())
    assert a.min() > b.max() or b.min() > a.max()
    # scores have the material contrast as size: +-0.5 around the mean
    assert abs(abs(a.mean() - b.mean()) - 1.0) < 0.02


def test_pca_false_colour_separates_materials_in_red_and_handles_nan():
    cube, _ = _two_material_cube(nan_rows=4)
    rgb = to_rgb8(cube, modality="hyperspectral")
    assert rgb.shape == (40, 50, 3) and rgb.dtype == np.uint8
    assert np.all(rgb[:4] == BACKGROUND_RGB)
    red_a, red_b = rgb[4:, :25, 0].astype(int), rgb[4:, 25:, 0].astype(int)
    assert abs(red_a.mean() - red_b.mean()) > 200
    assert red_a.min() > red_b.max() or red_b.min() > red_a.max()
    assert np.array_equal(rgb, pca_false_colour(cube))


def test_three_chosen_bands():
    cube = np.zeros((6, 8, 10), np.float32)
    cube[:, :4, 7] = 1.0   # band 7 bright on the left
    cube[:3, :, 2] = 1.0   # band 2 bright at the top
    out = to_rgb8(cube, modality="hyperspectral", bands=(7, 2, 0), percentiles=(0, 100))
    assert np.all(out[:, :4, 0] == 255) and np.all(out[:, 4:, 0] == 0)
    assert np.all(out[:3, :, 1] == 255) and np.all(out[3:, :, 1] == 0)
    assert np.all(out[..., 2] == 0)
    with pytest.raises(ValueError):
        to_rgb8(cube, bands=(0, 1, 10))


def test_mosaic_tile_pattern_is_exact():
    H, W, t = 13, 17, 4
    cols = [(10, 0, 0), (0, 20, 0), (0, 0, 30)]
    imgs = [np.full((H, W, 3), c, np.uint8) for c in cols]
    out = mosaic(imgs, t)
    for r in range(H):
        for c in range(W):
            assert tuple(out[r, c]) == cols[((r // t) + (c // t)) % 3], (r, c)
    cb = checkerboard(imgs[0], imgs[1], 5)
    assert tuple(cb[0, 0]) == cols[0] and tuple(cb[0, 5]) == cols[1]
    assert tuple(cb[5, 5]) == cols[0] and tuple(cb[12, 4]) == cols[0] and tuple(cb[12, 16]) == cols[1]
    with pytest.raises(ValueError):
        mosaic([imgs[0], imgs[1][:5]], 4)


def test_blend_weights():
    a = np.full((3, 4, 3), 100, np.uint8)
    b = np.full((3, 4, 3), 200, np.uint8)
    assert np.array_equal(blend(a, b, 0.0), a) and np.array_equal(blend(a, b, 1.0), b)
    assert np.all(blend(a, b, 0.25) == 125)


def test_case_colours_are_the_papers_and_overlay_tints_only_coloured_codes():
    assert CASE_COLOURS[2] == (0, 255, 255)      # P2 cyan
    assert CASE_COLOURS[3] == (255, 255, 0)      # P3.1 yellow
    assert CASE_COLOURS[4] == (255, 0, 255)      # P3.2 magenta
    assert AREA_COLOURS[4] == (0, 255, 0)        # P4 green
    assert 0 not in CASE_COLOURS and 1 not in CASE_COLOURS and 6 not in AREA_COLOURS  # no overlay
    assert len({CASE_COLOURS[5], *[CASE_COLOURS[c] for c in (2, 3, 4)], AREA_COLOURS[4]}) == 5
    labels = [e[1] for e in display.legend("cases")]
    assert any("P2" in s for s in labels) and any("P3.2" in s for s in labels)
    base = np.full((2, 4, 3), 100, np.uint8)
    codes = np.array([[0, 1, 2, 3], [4, 5, 6, 2]], np.uint8)
    full = overlay(base, codes, CASE_COLOURS, 1.0)
    assert np.array_equal(full[0, :2], base[0, :2])                # P6, P1 untouched
    assert tuple(full[0, 2]) == (0, 255, 255) and tuple(full[1, 0]) == (255, 0, 255)
    half = overlay(base, codes, CASE_COLOURS, 0.5).astype(int)
    assert np.all(np.abs(half[0, 2] - np.array([50, 178, 178])) <= 1)
    assert np.array_equal(half[0, :2], base[0, :2])


def test_large_images_render():
    # a 4K frame through every path once (correctness of shapes; speed is in benchmarks/)
    rng = np.random.default_rng(1)
    img = rng.normal(25, 2, (2160, 3840)).astype(np.float32)
    out = to_rgb8(img, modality="thermal")
    assert out.shape == (2160, 3840, 3)
    ov = overlay(out, (img > 27).astype(np.uint8) * 2, CASE_COLOURS, 0.4)
    assert np.array_equal(ov[img <= 27], out[img <= 27])


def test_depth_zero_is_no_measurement():
    d = np.tile(np.arange(0, 1001, 10, dtype=np.uint16), (3, 1))  # 0 (invalid), 10 .. 1000 mm
    out = to_rgb8(d, modality="depth", percentiles=(0, 100))
    assert np.all(out[:, 0] == BACKGROUND_RGB)
    lut = display.colormap_lut("viridis")
    assert np.array_equal(out[0, 1], lut[0]) and np.array_equal(out[0, -1], lut[255])  # 10 -> first, 1000 -> last


@pytest.mark.parametrize("finite_share", [0.1, 0.9])
def test_finite_rows_is_numpys_all_finite(finite_share):
    # the shortcut (first band, then the other bands of candidate rows, or all rows when most are
    # candidates) against the definition, with a non-finite value in any band
    rng = np.random.default_rng(7)
    a = rng.normal(size=(5000, 37)).astype(np.float32)
    a[rng.uniform(size=5000) > finite_share, 0] = np.nan
    a[rng.integers(0, 5000, 300), rng.integers(1, 37, 300)] = rng.choice([np.nan, np.inf, -np.inf], 300)
    truth = np.isfinite(a).all(axis=1)
    assert np.array_equal(display.finite_rows(a), truth)
    assert np.array_equal(display.finite_rows(a[:, :1]), np.isfinite(a[:, 0]))
    assert display.finite_rows(np.ones((4, 3), np.uint8)).all()


# ---------------------------------------------------------------------- block-wise rendering (issue 10)
def _reference_u8(a: np.ndarray, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """The stretch written out on the whole array: u = a * s - lo * s in float32, clipped to
    0..255, +0.5, truncated; NaN -> 0; mask = any band not finite."""
    a = np.asarray(a, dtype=np.float32)
    s = 255.0 / (hi - lo)
    u = np.multiply(a, np.float32(s))
    u -= np.float32(lo * s)
    with np.errstate(invalid="ignore"):
        u = np.clip(u, 0.0, 255.0)
    u[np.isnan(u)] = 0.0
    bad = ~np.isfinite(a)
    return (u + np.float32(0.5)).astype(np.uint8), (bad if a.ndim == 2 else bad.any(axis=2))


@pytest.mark.parametrize("shape", [(1, 1), (7, 5), (300, 901), (301, 877, 3), (5, 3, 4), (2, 70000, 3)])
def test_blockwise_stretch_equals_the_whole_array_formula(shape, monkeypatch):
    rng = np.random.default_rng(sum(shape))
    a = (rng.normal(50.0, 40.0, shape)).astype(np.float32)  # values beyond both limits too
    flat = a.reshape(-1)
    k = flat.size
    flat[rng.choice(k, k // 7, replace=False)] = np.nan
    flat[rng.choice(k, k // 50 + 1, replace=False)] = np.inf
    flat[rng.choice(k, k // 50 + 1, replace=False)] = -np.inf
    flat[0] = -0.0
    flat[-1] = np.nan
    want, want_nan = _reference_u8(a, 3.5, 97.25)
    for block in (display._BLOCK_VALUES, 1000, 1):  # blocks of many rows, a few rows, one row
        monkeypatch.setattr(display, "_BLOCK_VALUES", block)
        got, nan = display._normalise_u8(a, 3.5, 97.25)
        assert got.dtype == np.uint8 and np.array_equal(got, want)
        assert (nan is None and not want_nan.any()) or np.array_equal(nan, want_nan)
    # a strided view, float64 and integer input take the same path
    got, _ = display._normalise_u8(a[:, ::2], 3.5, 97.25)
    assert np.array_equal(got, _reference_u8(a[:, ::2], 3.5, 97.25)[0])
    ints = rng.integers(0, 4000, shape).astype(np.uint16)
    got, nan = display._normalise_u8(ints, 100.0, 3000.0)
    assert nan is None and np.array_equal(got, _reference_u8(ints, 100.0, 3000.0)[0])
    f64 = a.astype(np.float64)
    assert np.array_equal(display._normalise_u8(f64, 3.5, 97.25)[0], want)


def test_background_paint_and_fill_are_the_colour_exactly():
    rng = np.random.default_rng(3)
    for h, w in [(1, 1), (5, 7), (333, 1000)]:
        rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        mask = rng.random((h, w)) < 0.6
        want = rgb.copy()
        want[mask] = BACKGROUND_RGB
        display._paint_background(rgb, mask)
        assert np.array_equal(rgb, want)
        assert np.array_equal(display._background(h, w), np.broadcast_to(np.uint8(BACKGROUND_RGB), (h, w, 3)))
    view = np.zeros((10, 20, 3), np.uint8)[:, ::2]  # not contiguous: the numpy path
    display._paint_background(view, np.eye(10, dtype=bool))
    assert (view[np.eye(10, dtype=bool)] == BACKGROUND_RGB).all() and view[0, 1].tolist() == [0, 0, 0]


def test_channel_reductions_equal_numpys():
    rng = np.random.default_rng(4)
    b = rng.random((50, 60, 3)) < 0.2
    assert np.array_equal(display.any_channel(b), b.any(axis=2))
    a = rng.normal(size=(50, 60, 3)).astype(np.float32)
    a[b] = np.nan
    a[0, 0, 1] = np.inf
    assert np.array_equal(display.finite_rows(a.reshape(-1, 3)), np.isfinite(a).all(axis=2).ravel())


def test_pca_projection_of_a_run_of_rows_equals_the_gathered_rows():
    """A cube whose finite rows are one run is projected from views of it, one with a gap from
    gathered copies: the same chunks, the same basis, the same scores bit for bit."""
    rng = np.random.default_rng(5)
    n, bands = 70_000, 8  # more than one projection chunk (65536 rows)
    cube = (rng.normal(size=(1, n, bands)) @ rng.normal(size=(bands, bands))).astype(np.float32)
    gap = np.insert(cube, 40_000, np.nan, axis=1)  # one NaN pixel in the middle of the first chunk
    a = pca_scores(cube)
    b = pca_scores(gap)
    assert np.isnan(b[0, 40_000]).all()
    assert np.array_equal(np.delete(b, 40_000, axis=1), a)


def test_three_band_8bit_cube_is_drawn_as_rgb_raw_and_registered():
    """A hyperspectral camera's own 3-band 8-bit rendering (the Plant3DImageReg 'hs' PNGs) was drawn
    as a PCA false colour: a grey background came out green. It is RGB now, as recorded; its
    registered version (float32, NaN where not mapped) too, with the hues kept."""
    from plantreg_gui.models.layers import pca_basis

    raw = np.empty((20, 30, 3), np.uint8)
    raw[:] = (120, 120, 120)             # grey background
    raw[5:15, 5:20] = (60, 140, 40)      # a green leaf
    raw[5:15, 20:28] = (170, 50, 40)     # a red leaf
    out = to_rgb8(raw, modality="hyperspectral")
    assert np.array_equal(out, raw)
    assert display.shows_as_rgb(3, "hyperspectral") and display.shows_as_rgb(3, None)
    assert pca_basis(raw, "hyperspectral") is None  # no PCA basis imposed on the registered image
    reg = raw.astype(np.float32)
    reg[:3] = np.nan                     # not mapped
    out = to_rgb8(reg, modality="hyperspectral", percentiles=(0, 100))
    assert np.all(out[:3] == BACKGROUND_RGB)
    np.testing.assert_array_equal(out, to_rgb8(reg, modality="rgb", percentiles=(0, 100)))
    grey, green, red = out[18, 2].astype(int), out[10, 10].astype(int), out[10, 24].astype(int)
    assert grey[0] == grey[1] == grey[2]  # grey stays grey
    assert green[1] > green[0] > green[2] and red[0] > red[1] > red[2]


def test_many_band_cubes_keep_pca_false_colour():
    cube, _ = _two_material_cube()
    assert not display.shows_as_rgb(cube.shape[2], "hyperspectral")
    np.testing.assert_array_equal(to_rgb8(cube, modality="hyperspectral"), pca_false_colour(cube))
    four = np.random.default_rng(1).random((6, 7, 4)).astype(np.float32)
    assert not display.shows_as_rgb(4, "hyperspectral") and display.shows_as_rgb(4, "rgb")
    np.testing.assert_array_equal(to_rgb8(four, modality="hyperspectral"), pca_false_colour(four))
