"""Tests of the series readers (osmobulge.imaging.io).

Small series are written in every format (tifffile incl. OME and ImageJ
metadata, PNG/JPEG via Pillow, CZI via pylibCZIrw when installed), then read
back and compared with the frames that were written.
"""

import datetime as dt
import math
import tracemalloc
import warnings

import numpy as np
import pytest
import tifffile
from PIL import Image

from osmobulge.imaging.io import (
    FrameReadError,
    MetadataError,
    open_series,
    read_truth,
    write_series,
    write_truth,
)

PX = 1.3e-6


@pytest.fixture(scope="module")
def frames16():
    rng = np.random.default_rng(0)
    return rng.integers(0, 65535, (5, 24, 32), dtype=np.uint16)


@pytest.fixture(scope="module")
def frames8():
    rng = np.random.default_rng(1)
    return rng.integers(0, 255, (5, 24, 32), dtype=np.uint8)


def _stack(series):
    return np.stack([series[i] for i in range(len(series))])


# --------------------------------------------------------------------------------------
# every format round-trips pixels, pixel size and times
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["tiff", "ome-tiff", "tiff-folder", "png"])
def test_round_trip_16_bit(tmp_path, frames16, fmt):
    times = np.array([0.0, 60.0, 125.0, 180.0, 240.5])
    path = write_series(frames16, tmp_path / fmt, fmt=fmt, pixel_size=PX, timestamps=times)
    with open_series(path) as s:
        assert s.shape == frames16.shape
        assert s.dtype == np.uint16
        np.testing.assert_array_equal(_stack(s), frames16)
        assert s.pixel_size == pytest.approx(PX, rel=1e-4, abs=0)
        assert s.metadata_source == {"pixel_size": "file", "timestamps": "file"}
        if fmt == "tiff":  # ImageJ stores one frame interval
            np.testing.assert_allclose(s.timestamps, np.arange(5) * np.median(np.diff(times)))
        else:
            np.testing.assert_allclose(s.timestamps, times, atol=1e-6)
        assert s.names[0].startswith("frame")


@pytest.mark.parametrize("fmt", ["tiff", "ome-tiff", "tiff-folder", "png"])
def test_peek_is_the_frame_without_a_copy_where_memory_mapped(tmp_path, frames16, fmt):
    path = write_series(frames16, tmp_path / fmt, fmt=fmt, pixel_size=PX, timestamps=60.0 * np.arange(5))
    with open_series(path) as s:
        for i in (0, 3, -1):
            view = s.peek(i)
            np.testing.assert_array_equal(view, s[i])
            if fmt in ("tiff", "ome-tiff"):  # uncompressed, contiguous: a read-only view of the mapped file
                assert not view.flags.owndata and not view.flags.writeable
                assert s[i].flags.owndata  # while series[i] is a copy
        with pytest.raises(IndexError):
            s.peek(5)


def test_jpeg_round_trip_is_close(tmp_path, frames8):
    smooth = np.repeat(np.repeat(np.linspace(20, 230, 5 * 6 * 8).reshape(5, 6, 8), 4, axis=1), 4, axis=2)
    smooth = smooth.astype(np.uint8)
    path = write_series(smooth, tmp_path / "j", fmt="jpeg", pixel_size=PX, timestamps=np.arange(5) * 30.0)
    with open_series(path) as s:
        assert s.dtype == np.uint8
        assert np.abs(_stack(s).astype(int) - smooth).max() <= 6  # lossy
        np.testing.assert_allclose(s.timestamps, np.arange(5) * 30.0)
        assert s.pixel_size == pytest.approx(PX, rel=1e-4, abs=0)
    with pytest.raises(ValueError, match="8-bit"):
        write_series(np.zeros((1, 8, 8), np.uint16), tmp_path / "j16", fmt="jpeg", pixel_size=PX)


def test_array_source_and_dask(frames16):
    with pytest.raises(MetadataError, match="pixel_size="):
        open_series(frames16, frame_interval=10.0)
    with pytest.raises(MetadataError, match="frame_interval="):
        open_series(frames16, pixel_size=PX)
    s = open_series(frames16, pixel_size=PX, frame_interval=10.0)
    np.testing.assert_allclose(s.timestamps, np.arange(5) * 10.0)
    np.testing.assert_array_equal(s.to_dask().compute(), frames16)
    sub = s[1:4]
    assert len(sub) == 3
    np.testing.assert_array_equal(sub[0], frames16[1])
    np.testing.assert_allclose(sub.timestamps, [10.0, 20.0, 30.0])
    assert s[-1].shape == (24, 32)
    with pytest.raises(IndexError):
        s[5]


# --------------------------------------------------------------------------------------
# metadata: conflicts and missing values are clear errors
# --------------------------------------------------------------------------------------
def test_metadata_conflicts_raise(tmp_path, frames16):
    path = write_series(frames16, tmp_path / "o", fmt="ome-tiff", pixel_size=PX, timestamps=np.arange(5) * 60.0)
    with pytest.raises(MetadataError, match=r"pixel size conflict.*pixel_size="):
        open_series(path, pixel_size=1.0e-6)
    with pytest.raises(MetadataError, match="frame interval conflict"):
        open_series(path, frame_interval=30.0)
    with pytest.raises(MetadataError, match="timestamps conflict"):
        open_series(path, timestamps=np.arange(5) * 61.0)
    # agreeing values are fine, within rtol
    with open_series(path, pixel_size=PX * (1 + 1e-5), frame_interval=60.0) as s:
        assert s.pixel_size == pytest.approx(PX, rel=1e-6, abs=0)


def test_missing_metadata_names_what_to_set(tmp_path, frames16):
    plain = tmp_path / "plain.tif"
    tifffile.imwrite(plain, frames16)  # no resolution, no times
    with pytest.raises(MetadataError, match=r"pixel size not in the metadata.*pixel_size=.*pixel_size_um"):
        open_series(plain, frame_interval=5.0)
    with pytest.raises(MetadataError, match=r"timestamps not in the metadata.*frame_interval=.*frame_interval_min"):
        open_series(plain, pixel_size=PX)
    with pytest.warns(UserWarning, match="pixel size not in"):
        s = open_series(plain, frame_interval=5.0, missing="warn")
    assert math.isnan(s.pixel_size)
    s.close()
    with open_series(plain, pixel_size=PX, frame_interval=5.0) as s:
        assert s.metadata_source == {"pixel_size": "argument", "timestamps": "argument"}
        np.testing.assert_array_equal(_stack(s), frames16)


def test_display_dpi_is_not_a_pixel_size(tmp_path, frames8):
    """72 dpi is a display default; 1 um/px in cm units is a calibration (ECOSYSTEM gotcha 9)."""
    f72 = tmp_path / "dpi72.tif"
    tifffile.imwrite(f72, frames8, resolution=(72, 72), resolutionunit="INCH")
    with pytest.raises(MetadataError, match="pixel size not in"):
        open_series(f72, frame_interval=1.0)
    fcm = tmp_path / "cm.tif"
    tifffile.imwrite(fcm, frames8, resolution=(1e4, 1e4), resolutionunit="CENTIMETER")
    with open_series(fcm, frame_interval=1.0) as s:
        assert s.pixel_size == pytest.approx(1e-6)
    fum = tmp_path / "um.tif"
    tifffile.imwrite(fum, frames8, resolution=(1 / 0.5, 1 / 0.5), resolutionunit="MICROMETER")
    with open_series(fum, frame_interval=1.0) as s:
        assert s.pixel_size == pytest.approx(0.5e-6)


# --------------------------------------------------------------------------------------
# folders: order, bad frames, colour
# --------------------------------------------------------------------------------------
def _png(path, arr, when=None):
    im = Image.fromarray(arr)
    kw = {}
    if when is not None:
        exif = Image.Exif()
        exif.get_ifd(0x8769)[36867] = when.strftime("%Y:%m:%d %H:%M:%S")
        kw["exif"] = exif.tobytes()
    im.save(path, **kw)


def test_natural_order_without_timestamps(tmp_path, frames8):
    for k in (10, 2, 1):
        _png(tmp_path / f"frame{k}.png", frames8[k % 5])
    (tmp_path / "notes.txt").write_text("not an image, ignored")
    with open_series(tmp_path, pixel_size=PX, frame_interval=60.0) as s:
        assert s.names == ["frame1.png", "frame2.png", "frame10.png"]
        np.testing.assert_array_equal(s[2], frames8[0])


def test_list_of_files_like_a_glob(tmp_path, frames8):
    """A frames glob's matches (experiment.toml `frames = "frames/*.png"`) open as a series."""
    for k in (10, 2, 1, 3):
        _png(tmp_path / f"frame{k}.png", frames8[k % 5])
    files = sorted(tmp_path.glob("frame*.png"))[:3]  # frame1, frame10, frame2 in plain sort
    with open_series([str(f) for f in files], pixel_size=PX, frame_interval=60.0) as s:
        assert s.names == ["frame1.png", "frame2.png", "frame10.png"]  # natural order
        np.testing.assert_array_equal(s[1], frames8[2])
        np.testing.assert_allclose(s.timestamps, [0, 60, 120])
    with pytest.raises(FileNotFoundError, match="no such image file"):
        open_series([files[0], tmp_path / "missing.png"], pixel_size=PX, frame_interval=60.0)


def test_timestamp_order_wins_over_names(tmp_path, frames8):
    t0 = dt.datetime(2024, 5, 1, 12, 0, 0)
    # names in reverse of the acquisition order
    for k in range(4):
        _png(tmp_path / f"img{k}.png", frames8[k], t0 + dt.timedelta(minutes=10 * (3 - k)))
    with open_series(tmp_path, pixel_size=PX) as s:
        assert s.names == ["img3.png", "img2.png", "img1.png", "img0.png"]
        np.testing.assert_allclose(s.timestamps, [0, 600, 1200, 1800])
        assert s.start_time == "2024-05-01T12:00:00"
    with open_series(tmp_path, pixel_size=PX, order="name") as s:
        assert s.names == ["img0.png", "img1.png", "img2.png", "img3.png"]
    _png(tmp_path / "img9.png", frames8[4])  # one file without a time
    with pytest.raises(MetadataError, match="order='time'"):
        open_series(tmp_path, pixel_size=PX, order="time")
    with open_series(tmp_path, pixel_size=PX, frame_interval=60.0) as s:  # auto: falls back to names
        assert s.names[-1] == "img9.png" and s.metadata_source["timestamps"] == "argument"


@pytest.mark.parametrize("fmt", ["png", "tiff-folder", "jpeg"])
def test_truncated_frame_is_flagged_and_skipped(tmp_path, frames8, fmt):
    times = np.arange(5) * 60.0
    folder = write_series(frames8, tmp_path / fmt, fmt=fmt, pixel_size=PX, timestamps=times)
    victim = sorted(folder.iterdir())[2]
    data = victim.read_bytes()
    victim.write_bytes(data[: len(data) // 2])
    with pytest.warns(UserWarning, match=victim.name):
        s = open_series(folder)
    assert len(s) == 4
    assert [n for n, _ in s.bad_frames] == [victim.name]
    assert victim.name not in s.names
    np.testing.assert_allclose(s.timestamps, [0, 60, 180, 240])
    if fmt != "jpeg":
        np.testing.assert_array_equal(s[2], frames8[3])
    # frames written over the series shape are flagged too
    _png(folder / "zz_wrong_size.png", np.zeros((8, 8), np.uint8))
    with pytest.warns(UserWarning):
        s2 = open_series(folder, order="name", frame_interval=60.0 if fmt == "png" else None)
    assert "zz_wrong_size.png" in [n for n, _ in s2.bad_frames]


def test_garbage_with_image_extension_is_flagged(tmp_path, frames8):
    for k in range(3):
        _png(tmp_path / f"f{k}.png", frames8[k])
    (tmp_path / "f1b.png").write_bytes(b"this is no png at all" * 10)
    with pytest.warns(UserWarning, match="f1b.png"):
        s = open_series(tmp_path, pixel_size=PX, frame_interval=1.0)
    assert len(s) == 3 and s.bad_frames[0][0] == "f1b.png"


def test_truncated_multipage_tiff_flags_the_lost_pages(tmp_path, frames16):
    path = write_series(frames16, tmp_path / "t", fmt="tiff", pixel_size=PX)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 24 * 32 * 2 - 100])  # cut into the last frame's data
    with pytest.warns(UserWarning, match=r"frames.tif\[4\]"):
        s = open_series(path)
    assert len(s) == 4
    np.testing.assert_array_equal(_stack(s), frames16[:4])


def test_a_file_that_is_not_an_image_is_an_error(tmp_path):
    txt = tmp_path / "notes.txt"
    txt.write_text("hello")
    with pytest.raises(ValueError, match="not an image series"):
        open_series(txt)
    fake = tmp_path / "fake.tif"
    fake.write_bytes(b"nope" * 100)
    with pytest.raises(ValueError, match="not a readable TIFF"):
        open_series(fake)
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "readme.md").write_text("x")
    with pytest.raises(ValueError, match="no image files"):
        open_series(empty)
    with pytest.raises(FileNotFoundError):
        open_series(tmp_path / "missing")


def test_colour_frames_become_luminance_grey(tmp_path):
    rgb = np.zeros((2, 4, 6, 3), np.uint8)
    rgb[..., 0] = 200
    rgb[..., 1] = 100
    rgb[..., 2] = 50
    for k in range(2):
        Image.fromarray(rgb[k]).save(tmp_path / f"c{k}.png")
    expect = round(0.2125 * 200 + 0.7154 * 100 + 0.0721 * 50)
    with open_series(tmp_path, pixel_size=PX, frame_interval=1.0) as s:
        assert s[0].shape == (4, 6) and s[0].dtype == np.uint8
        assert np.all(s[0] == expect)
    with open_series(tmp_path, pixel_size=PX, frame_interval=1.0, grey="green") as s:
        assert np.all(s[1] == 100)
    with open_series(tmp_path, pixel_size=PX, frame_interval=1.0, grey="mean") as s:
        assert np.all(s[1] == round(350 / 3))
    # 16-bit RGB TIFF stays 16-bit
    t16 = tmp_path / "rgb16.tif"
    tifffile.imwrite(t16, (rgb.astype(np.uint16) * 257), photometric="rgb")
    with open_series(t16, pixel_size=PX, frame_interval=1.0) as s:
        assert s.dtype == np.uint16 and s[0].dtype == np.uint16
        assert abs(int(s[0][0, 0]) - expect * 257) <= 257
    with pytest.raises(ValueError, match="grey"):
        open_series(tmp_path, pixel_size=PX, grey="sepia")


def test_multichannel_needs_a_channel(tmp_path):
    data = np.arange(3 * 2 * 8 * 8, dtype=np.uint16).reshape(3, 2, 8, 8)
    path = tmp_path / "tc.ome.tif"
    tifffile.imwrite(path, data, ome=True, metadata={"axes": "TCYX", "PhysicalSizeX": 1.0, "PhysicalSizeY": 1.0})
    with pytest.raises(ValueError, match="channel="):
        open_series(path, frame_interval=1.0)
    with open_series(path, frame_interval=1.0, channel=1) as s:
        assert len(s) == 3
        np.testing.assert_array_equal(s[2], data[2, 1])
        assert s.pixel_size == pytest.approx(1e-6)


def test_a_stack_of_four_saved_as_planar_colour_says_how_to_save_it(tmp_path):
    """tifffile.imwrite of a (4, H, W) stack writes one planar RGBA page: the error names the fix."""
    data = np.zeros((4, 16, 16), np.uint16)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (tifffile may warn about the guessed photometric)
        tifffile.imwrite(tmp_path / "four.tif", data)
    with pytest.raises(ValueError, match="unsupported axes 'SYX'.*photometric='minisblack'"):
        open_series(tmp_path / "four.tif", pixel_size=1e-6, frame_interval=1.0)
    tifffile.imwrite(tmp_path / "four-grey.tif", data, photometric="minisblack")
    with open_series(tmp_path / "four-grey.tif", pixel_size=1e-6, frame_interval=1.0) as s:
        assert len(s) == 4


# --------------------------------------------------------------------------------------
# laziness
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("compression", [None, "zlib"])
def test_opening_reads_no_pixels_and_memory_stays_flat(tmp_path, monkeypatch, compression):
    rng = np.random.default_rng(2)
    n, h, w = 200, 192, 256
    path = tmp_path / "big.tif"
    with tifffile.TiffWriter(path) as tw:
        for _ in range(n):  # one page at a time: the test itself never holds the series
            page = rng.integers(0, 65535, (h, w), dtype=np.uint16)
            tw.write(page, compression=compression, contiguous=compression is None)
    frame_bytes = h * w * 2
    reads = {"n": 0}
    real = tifffile.TiffPage.asarray

    def counting(self, *a, **k):
        reads["n"] += 1
        return real(self, *a, **k)

    monkeypatch.setattr(tifffile.TiffPage, "asarray", counting)
    tracemalloc.start()
    try:
        s = open_series(path, pixel_size=PX, frame_interval=1.0)
        _, peak_open = tracemalloc.get_traced_memory()
        assert len(s) == n
        assert reads["n"] == 0
        assert peak_open < 0.15 * n * frame_bytes  # the IFDs (~10 kB a page), not the pixels
        cur_open, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for k in range(20):
            float(s[k][0, 0])
        _, peak_20 = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for k in range(20, n):
            float(s[k][0, 0])
        cur_all, peak_all = tracemalloc.get_traced_memory()
        # flat in the number of frames: reading 180 more frames keeps no pixels (holding them
        # would add 180 frames = 17.7 MB; tifffile's per-page bookkeeping grows by ~1.5 kB a
        # page read, and a full test run adds a few hundred kB of unrelated interpreter noise)
        assert peak_all < peak_20 + 5 * frame_bytes
        assert cur_all < cur_open + 5 * frame_bytes
        assert peak_20 < cur_open + 10 * frame_bytes  # decoding buffers of one frame, not 20 frames
        assert reads["n"] == (n if compression else 0)  # memory-mapped when uncompressed
        s.close()
    finally:
        tracemalloc.stop()


# --------------------------------------------------------------------------------------
# CZI
# --------------------------------------------------------------------------------------
def test_czi_reader(tmp_path, frames16):
    pyczi = pytest.importorskip("pylibCZIrw.czi", reason="pylibCZIrw writes the test CZI files")
    path = tmp_path / "s.czi"
    with pyczi.create_czi(str(path), exist_ok=True) as w:
        for t in range(frames16.shape[0]):
            w.write(data=frames16[t][..., None], plane={"T": t, "Z": 0, "C": 0})
        w.write_metadata(scale_x=PX, scale_y=PX)  # CZI Scaling is in metres
    with pytest.raises(MetadataError, match="frame_interval="):
        open_series(path)  # pylibCZIrw writes no acquisition times
    with open_series(path, frame_interval=600.0) as s:
        assert s.kind == "czi" and s.shape == frames16.shape and s.dtype == np.uint16
        np.testing.assert_array_equal(_stack(s), frames16)
        assert s.pixel_size == pytest.approx(PX)
    with pytest.raises(MetadataError, match="conflict"):
        open_series(path, frame_interval=600.0, pixel_size=2e-6)
    # a writer that put micrometres in the metres field: read as um, with a warning
    bad = tmp_path / "um.czi"
    with pyczi.create_czi(str(bad), exist_ok=True) as w:
        w.write(data=frames16[0][..., None], plane={"T": 0, "Z": 0, "C": 0})
        w.write_metadata(scale_x=1.3, scale_y=1.3)
    with pytest.warns(UserWarning, match="reading it as um"), open_series(bad) as s:
        assert s.pixel_size == pytest.approx(1.3e-6)


# --------------------------------------------------------------------------------------
# synthetic series on disk
# --------------------------------------------------------------------------------------
def test_synthetic_save_and_reload(tmp_path):
    from osmobulge.imaging.synthetic import Nuisances, render_series

    s = render_series(
        [0.5, 1.0],
        chamber=(100e-6, 50e-6, 10e-6),
        shape=(400, 420),
        times=[0.0, 900.0],
        nuisances=Nuisances(bit_depth=12, fractured_frames=(1,)),
    )
    out = s.save(tmp_path / "syn", fmt="ome-tiff")
    truth = read_truth(tmp_path / "syn")
    assert list(truth.flag.values) == ["ok", "fractured"]
    np.testing.assert_allclose(truth.profile_z.values, s.truth.profile_z.values)
    assert truth.attrs["pixel_size"] == s.truth.attrs["pixel_size"]
    with open_series(out) as fs:
        np.testing.assert_array_equal(_stack(fs), s.frames)
        assert fs.pixel_size == pytest.approx(1e-6)
        np.testing.assert_allclose(fs.timestamps, [0.0, 900.0])
    write_truth(truth, tmp_path / "again")  # atomic rewrite of a loaded dataset
    assert not list((tmp_path / "again").glob(".*tmp"))
    with pytest.raises(ValueError, match="fmt"):
        s.save(tmp_path / "x", fmt="bmp")


def test_open_series_validation(tmp_path, frames16):
    with pytest.raises(ValueError, match="order"):
        open_series(frames16, pixel_size=PX, frame_interval=1.0, order="random")
    with pytest.raises(ValueError, match="missing"):
        open_series(frames16, pixel_size=PX, frame_interval=1.0, missing="ignore")
    with pytest.raises(ValueError, match="not both"):
        open_series(frames16, pixel_size=PX, frame_interval=1.0, timestamps=np.arange(5.0))
    with pytest.raises(ValueError, match="metres per pixel"):
        open_series(frames16, pixel_size=1.3, frame_interval=1.0)
    with pytest.raises(ValueError, match="timestamps must be 5"):
        open_series(frames16, pixel_size=PX, timestamps=[0.0, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = open_series(frames16[:1], pixel_size=PX)  # one frame needs no time base
    assert s.timestamps.tolist() == [0.0]


def test_frame_read_error_is_flagged_and_skipped_on_iteration(tmp_path, frames8):
    for k in range(3):
        _png(tmp_path / f"f{k}.png", frames8[k])
    s = open_series(tmp_path, pixel_size=PX, frame_interval=1.0)
    (tmp_path / "f1.png").write_bytes(b"\x89PNG broken after opening")
    with pytest.raises(FrameReadError, match="f1.png"):
        s[1]
    assert s.bad_frames[-1][0] == "f1.png"
    with pytest.warns(UserWarning, match="skipping frame 1"):
        got = [k for k, _ in s.iter_frames()]
    assert got == [0, 2]
