"""Region statistics (core/registration/region.py) against a hand-made result whose every value is known
(tests/test_export.py: a plane seen by the ir target, thermal = 20 + 0.1 * column, cube band b =
100 * b + row, known case counts)."""

import csv
import io

import numpy as np
import pytest

from plantreg_gui.core.errors import InputError
from plantreg_gui.core.registration.hits import HitImage
from plantreg_gui.core.registration.region import region_mask, region_stats, stats_csv

from test_export import C0, C1, NB, R0, R1, _result


def test_rectangle_and_polygon_masks():
    m = region_mask((30, 40), rect=(10, 5, 14, 8))  # x 10..13, y 5..7
    assert m.sum() == 12 and m[5:8, 10:14].all()
    assert (region_mask((30, 40), rect=(14, 8, 10, 5)) == m).all()  # either corner order
    assert region_mask((30, 40), rect=(-5, -5, 2, 100)).sum() == 2 * 30  # clipped
    # a triangle with its right angle at the origin: pixel centres (c + .5, r + .5) with c + r + 1 <= 10
    tri = region_mask((30, 40), polygon=[(0, 0), (10, 0), (0, 10)])
    rr, cc = np.mgrid[0:30, 0:40]
    inside = (cc + 0.5) + (rr + 0.5) < 10
    assert np.sum(tri != inside) <= 10  # boundary pixels may go either way (10 centres lie on the edge)
    assert tri[0, 0] and tri[4, 4] and not tri[5, 5]
    with pytest.raises(InputError):
        region_mask((30, 40), polygon=[(0, 0), (1, 1)])


def test_thermal_mean_over_p1_not_mixed():
    rig, res = _result()
    # the whole object minus its first two rows (thermal not mapped there): the thermal case map
    # has P2 on row R0+1 cols C0..C0+4, P3.1 on R0+10, P3.2 on R0+11, P5 on R1-1, outside on R0+12
    mask = region_mask(res.shape, rect=(C0, R0 + 2, C1, R1))
    mixed = np.zeros(res.shape, bool)
    mixed[R0 + 5, C0:C1] = True  # one row of P1 flagged mixed: excluded from the statistics
    res.mixed = {"thermal": mixed}
    s = region_stats(res, mask, "thermal", unit="°C")
    n = (R1 - R0 - 2) * (C1 - C0)
    assert s.pixels == n
    assert s.cases["P3.1"] == (3, pytest.approx(100 * 3 / n))
    assert s.cases["P3.2"][0] == 4 and s.cases["P5"][0] == 24 and s.cases["out"][0] == 2
    assert s.cases["P2"][0] == 0  # thermal's P2 row (R0 + 1) is outside the region
    p1 = np.zeros(res.shape, bool)
    p1[mask] = res.cases["thermal"][mask] == 1
    assert s.cases["P1"][0] == p1.sum()
    assert s.mixed == C1 - C0
    p1 &= ~mixed
    cols = np.nonzero(p1)[1]
    truth = 20.0 + 0.1 * cols
    assert s.trusted == p1.sum()
    assert s.mean[0] == pytest.approx(truth.mean(), abs=1e-5)
    assert s.median[0] == pytest.approx(np.median(truth), abs=1e-5)
    assert s.std[0] == pytest.approx(truth.std(), abs=1e-5)


def test_cube_mean_spectrum_with_wavelengths_and_hit_image():
    rig, res = _result()
    wl = 400.0 + 10.0 * np.arange(NB)
    mask = region_mask(res.shape, rect=(C0 + 10, R0 + 2, C0 + 14, R0 + 6))  # all P1 in hs: rows R0+2..R0+5
    dense = res.registered["hs"]
    flat = np.flatnonzero(np.isfinite(dense).all(axis=2).ravel())
    res.registered["hs"] = HitImage(flat, dense.reshape(-1, NB)[flat], dense.shape)  # the large-cube form
    s = region_stats(res, mask, "hs", wl)
    assert s.trusted == 16 and s.bands == NB
    # band b = 100 b + row, rows R0+2..R0+5: mean row R0+3.5
    assert np.allclose(s.mean, 100 * np.arange(NB) + R0 + 3.5)
    rows = list(csv.DictReader(io.StringIO(stats_csv([s], "rect"))))
    means = [r for r in rows if r["statistic"] == "mean"]
    assert [float(r["wavelength_nm"]) for r in means] == list(wl)
    assert [float(r["value"]) for r in means] == pytest.approx(list(s.mean))
    p1 = next(r for r in rows if r["statistic"] == "pixels" and r["case"] == "P1")
    assert p1["value"] == "16" and p1["source"] == "hs" and p1["region"] == "rect"


def test_empty_selection_gives_nan_not_an_error():
    rig, res = _result()
    s = region_stats(res, region_mask(res.shape, rect=(0, 0, 3, 3)), "thermal")  # background corner
    assert s.trusted == 0 and np.isnan(s.mean).all() and s.cases["P6"][0] == 9
    assert ",mean,P1 not mixed,,,," in stats_csv([s])


def _cube_result(seed=3):
    """A hand-made result: a 40 x 50 target whose 'hs' source is a 7-band HitImage with random
    values and a few NaN bands, P1 everywhere except a known block; truth from the arrays."""
    from types import SimpleNamespace

    H, W, B = 40, 50, 7
    rng = np.random.default_rng(seed)
    cube = (100.0 + 10.0 * rng.standard_normal((H, W, B))).astype(np.float32)
    cube[rng.random((H, W)) < 0.1, rng.integers(0, B)] = np.nan  # pixels with one band not finite
    hit = rng.random((H, W)) < 0.8
    flat = np.flatnonzero(hit.ravel())
    codes = np.ones((H, W), np.uint8)
    codes[30:, :10] = 2  # P2: not trusted
    mixed = np.zeros((H, W), bool)
    mixed[::7, ::3] = True
    res = SimpleNamespace(shape=(H, W), registered={"hs": HitImage(flat, cube.reshape(-1, B)[flat], (H, W, B))},
                          cases={"hs": codes}, mixed={"hs": mixed}, points_rig=np.zeros((H, W, 3), np.float32))
    return res, cube, hit, codes, mixed


@pytest.mark.parametrize("chunk", [5, 64, 1 << 22])  # one band / a few pixels at a time .. all at once
def test_chunked_cube_statistics_match_the_arrays(monkeypatch, chunk):
    from plantreg_gui.core.registration import region

    monkeypatch.setattr(region, "CHUNK", chunk)
    res, cube, hit, codes, mixed = _cube_result()
    mask = region_mask(res.shape, polygon=[(3, 2), (47, 5), (40, 38), (2, 35)])
    s = region_stats(res, mask, "hs")
    trusted = mask & hit & (codes == 1) & ~mixed & np.isfinite(cube).all(axis=2)
    v = cube[trusted].astype(np.float64)  # (n, B)
    assert s.trusted == trusted.sum() > 500 and s.pixels == mask.sum()
    assert s.mixed == (mask & (codes == 1) & mixed).sum()
    assert np.allclose(s.mean, v.mean(axis=0), atol=1e-4)
    assert np.allclose(s.std, v.std(axis=0), atol=1e-4)
    assert np.allclose(s.median, np.median(v, axis=0), atol=1e-5)


def test_statistics_are_cancellable_between_chunks(monkeypatch):
    from plantreg_gui.core.registration import region
    from plantreg_gui.core.errors import Cancelled
    from plantreg_gui.core.progress import CancelToken, Reporter

    monkeypatch.setattr(region, "CHUNK", 64)  # many chunks
    res, *_ = _cube_result()
    mask = np.ones(res.shape, bool)
    calls = []
    token = CancelToken()

    def cb(f, msg):
        calls.append(f)
        if len(calls) == 4:  # the user presses Cancel while the values are being read
            token.cancel()

    with pytest.raises(Cancelled):
        region_stats(res, mask, "hs", progress=Reporter(cb, token))
    assert len(calls) == 4  # stopped at the next chunk, not at the end
    full = []
    region_stats(res, mask, "hs", progress=Reporter(lambda f, m: full.append(f)))
    assert len(full) > 10 and full == sorted(full) and full[-1] == 1.0
