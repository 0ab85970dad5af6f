"""The ENVI cube reader (core/io/imageio.py) returns what spectral's own ``load()`` returns -- same
values, dtype and shape -- for every interleave, several dtypes and both byte orders, without
spectral's copies; and a data file shorter than its header is refused naming the file."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.parametrize("interleave", ["bsq", "bil", "bip"])
@pytest.mark.parametrize("dtype", ["<f4", ">f4", "<u2", ">i2", "<f8"])
def test_envi_cube_reads_as_spectral_loads_it(tmp_path, interleave, dtype):
    import spectral.io.envi as envi

    from plantreg_gui.core.io.imageio import read_image

    rng = np.random.default_rng(7)
    cube = (rng.random((9, 11, 5)) * 1000).astype(dtype)
    hdr = tmp_path / "cube.hdr"
    envi.save_image(str(hdr), cube, interleave=interleave, byteorder=int(np.dtype(dtype).byteorder == ">"),
                    dtype=np.dtype(dtype).newbyteorder("="), force=True)
    ours = read_image(hdr)
    ref = np.asarray(envi.open(str(hdr)).load())
    assert ours.shape == ref.shape == (9, 11, 5)
    assert ours.dtype == ref.dtype
    np.testing.assert_array_equal(ours, ref)
    np.testing.assert_array_equal(ours, cube.astype(ref.dtype))


def test_envi_data_shorter_than_its_header_is_refused(tmp_path):
    import spectral.io.envi as envi

    from plantreg_gui.core.errors import InputError
    from plantreg_gui.core.io.imageio import read_image

    hdr = tmp_path / "cube.hdr"
    envi.save_image(str(hdr), np.ones((8, 8, 4), np.float32), interleave="bsq", force=True)
    data = next(p for p in tmp_path.iterdir() if p.suffix != ".hdr")
    data.write_bytes(data.read_bytes()[:-40])
    with pytest.raises(InputError) as e:
        read_image(hdr)
    assert data.name in str(e.value) or "cube" in str(e.value)
