"""Images of a recording decoded in parallel threads (core.recording.read_images) and PNGs decoded
by imagecodecs (core.imageio): the same arrays as the files hold, errors in the order a one-by-one
read gives them, and a refused header before any pixel is decoded."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from plantreg_gui.core.errors import InputError
from plantreg_gui.core.io.imageio import read_image
from plantreg_gui.core.data.recording import Recording, read_images


def _png(path, a):
    import cv2

    b = a[..., ::-1] if a.ndim == 3 and a.shape[2] == 3 else (a[..., [2, 1, 0, 3]] if a.ndim == 3 else a)
    assert cv2.imwrite(str(path), np.ascontiguousarray(b))
    return path


@pytest.mark.parametrize("shape,dtype", [((37, 53), np.uint8), ((37, 53), np.uint16), ((37, 53, 3), np.uint8),
                                         ((37, 53, 4), np.uint8), ((37, 53, 3), np.uint16), ((37, 53, 4), np.uint16)])
def test_png_values_as_written(tmp_path, shape, dtype):
    a = np.random.default_rng(3).integers(0, np.iinfo(dtype).max, shape, dtype=dtype, endpoint=True)
    img = read_image(_png(tmp_path / "x.png", a))
    assert img.dtype == dtype and np.array_equal(img, a)  # RGB(A) order, values untouched


def test_png_palette_and_transparency_as_pillow_expands_them(tmp_path):
    # colour types imagecodecs is not used for (OpenCV decodes them): expanded to RGB as before
    rng = np.random.default_rng(4)
    idx = rng.integers(0, 16, (20, 30), dtype=np.uint8)
    pal = Image.fromarray(idx, mode="P")
    pal.putpalette(rng.integers(0, 256, 48, dtype=np.uint8).tolist())
    pal.save(tmp_path / "p.png")
    assert np.array_equal(read_image(tmp_path / "p.png"), np.asarray(pal.convert("RGB")))
    grey = Image.fromarray(idx * 16)
    grey.save(tmp_path / "t.png", transparency=0)  # a tRNS chunk
    assert np.array_equal(read_image(tmp_path / "t.png"), idx * 16)


def _files(tmp_path, rng):
    arrays = {"a.png": rng.integers(0, 65535, (40, 50), dtype=np.uint16),
              "b.png": rng.integers(0, 255, (60, 70, 3), dtype=np.uint8),
              "c.npy": rng.random((30, 20, 5)).astype(np.float32)}
    _png(tmp_path / "a.png", arrays["a.png"])
    _png(tmp_path / "b.png", arrays["b.png"])
    np.save(tmp_path / "c.npy", arrays["c.npy"])
    import tifffile

    arrays["d.tif"] = rng.random((33, 44)).astype(np.float32)
    tifffile.imwrite(tmp_path / "d.tif", arrays["d.tif"])
    return arrays


def test_read_images_gives_the_files_arrays_in_order(tmp_path):
    arrays = _files(tmp_path, np.random.default_rng(5))
    calls = []
    out = read_images([tmp_path / n for n in arrays], while_decoding=lambda: calls.append(1))
    assert calls == [1]
    for (name, a), img in zip(arrays.items(), out):
        assert img.dtype == a.dtype and np.array_equal(img, a), name


def test_read_images_reports_the_first_bad_file_in_list_order(tmp_path):
    arrays = _files(tmp_path, np.random.default_rng(6))
    (tmp_path / "bad1.png").write_bytes(b"not a png at all")
    (tmp_path / "bad2.tif").write_bytes(b"II*\0garbage")
    names = list(arrays)
    calls = []
    with pytest.raises(InputError) as e:
        read_images([tmp_path / names[0], tmp_path / "bad1.png", tmp_path / names[1], tmp_path / "bad2.tif"],
                    while_decoding=lambda: calls.append(1))
    assert "bad1.png" in str(e.value) and calls == []  # nothing long started for a refused recording
    with pytest.raises(InputError) as e:
        read_images([tmp_path / n for n in names] + [tmp_path / "bad2.tif"])
    assert "bad2.tif" in str(e.value)


def test_a_refused_header_stops_the_read_before_any_pixel_is_decoded(tmp_path, monkeypatch):
    import plantreg_gui.core.data.recording as recording

    arrays = _files(tmp_path, np.random.default_rng(8))
    (tmp_path / "bad.tif").write_bytes(b"II*\0garbage")
    decoded = []
    real = recording.image_decoder

    def watched(path):
        d = real(path)

        def decode():
            decoded.append(path)
            return d()
        decode.pixel_file = d.pixel_file
        return decode

    monkeypatch.setattr(recording, "image_decoder", watched)
    with pytest.raises(InputError) as e:
        read_images([tmp_path / n for n in arrays] + [tmp_path / "bad.tif"])
    assert "bad.tif" in str(e.value) and decoded == []
    # the same files without the bad one: every one decoded (the watch itself works)
    read_images([tmp_path / n for n in arrays])
    assert len(decoded) == len(arrays)


def test_recording_load_reads_every_image(tmp_path):
    rng = np.random.default_rng(7)
    rec = Recording(None, rng.integers(1, 4000, (24, 32), dtype=np.uint16),
                    {"ir": rng.integers(0, 65535, (24, 32), dtype=np.uint16),
                     "rgb": rng.integers(0, 255, (48, 64, 3), dtype=np.uint8),
                     "cube": rng.random((16, 16, 9)).astype(np.float32)})
    rec.save(tmp_path, {"ir": "ir.png", "rgb": "rgb.png"})
    back = Recording.load(tmp_path)
    assert np.array_equal(back.depth, rec.depth)
    for name, a in rec.images.items():
        assert back.images[name].dtype == a.dtype and np.array_equal(back.images[name], a), name
