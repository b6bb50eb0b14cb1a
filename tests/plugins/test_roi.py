"""CSV and ImageJ ROI import/export of picked points: pure functions, no Qt."""

import numpy as np
import pytest

from osmobulge.plugins import roi

roifile = pytest.importorskip("roifile")


@pytest.fixture
def points():
    rng = np.random.default_rng(7)
    return {
        0: rng.uniform(0, 500, size=(5, 2)),
        3: rng.uniform(0, 500, size=(9, 2)),
        12: rng.uniform(0, 500, size=(2, 2)),
    }


def _assert_same(a, b, atol):
    assert sorted(a) == sorted(b)
    for f in a:
        np.testing.assert_allclose(a[f], b[f], atol=atol)


def test_csv_round_trip_keeps_order_and_precision(points, tmp_path):
    path = roi.write_points_csv(tmp_path / "p.csv", points)
    _assert_same(points, roi.read_points_csv(path), atol=0)
    text = path.read_text().splitlines()
    assert text[0] == "frame,point,x_px,y_px"
    # x is the column, y the row
    f, k, x, y = text[1].split(",")
    assert (int(f), int(k)) == (0, 0)
    assert float(x) == points[0][0, 1] and float(y) == points[0][0, 0]


def test_csv_micrometre_columns(points, tmp_path):
    path = roi.write_points_csv(tmp_path / "p.csv", points, pixel_size_um=1.6)
    header = path.read_text().splitlines()[0]
    assert header == "frame,point,x_px,y_px,x_um,y_um"
    # a table with micrometre columns only (e.g. from a spreadsheet)
    um = tmp_path / "um.csv"
    um.write_text("frame,x_um,y_um\n2,16.0,3.2\n2,32.0,4.8\n")
    got = roi.read_points_csv(um, pixel_size_um=1.6)
    np.testing.assert_allclose(got[2], [[2.0, 10.0], [3.0, 20.0]])
    with pytest.raises(ValueError, match="pixel_size_um"):
        roi.read_points_csv(um)


def test_csv_point_column_orders_rows(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("frame,point,x_px,y_px\n1,1,5,6\n1,0,1,2\n")
    np.testing.assert_array_equal(roi.read_points_csv(path)[1], [[2, 1], [6, 5]])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("x_px,y_px\n1,2\n", "'frame' column"),
        ("frame,a,b\n1,2,3\n", "x_px,y_px"),
        ("frame,x_px,y_px\n1,two,3\n", "line 2: not a number"),
        ("frame,x_px,y_px\n1.5,2,3\n", "non-negative integer"),
        ("frame,x_px,y_px\n1,nan,3\n", "non-finite"),
    ],
)
def test_csv_errors(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        roi.read_points_csv(path)


@pytest.mark.parametrize("kind", roi.ROI_KINDS)
def test_imagej_zip_round_trip(points, tmp_path, kind):
    path = roi.write_points_imagej(tmp_path / "set.zip", points, kind=kind)
    rois = roifile.roiread(path)
    assert [r.name for r in rois] == ["frame-0000", "frame-0003", "frame-0012"]
    expected = roifile.ROI_TYPE.POINT if kind == "point" else roifile.ROI_TYPE.POLYLINE
    assert all(r.roitype == expected for r in rois)
    assert [r.t_position for r in rois] == [1, 4, 13]
    # ImageJ pixel-corner convention: stored x = col + 0.5
    np.testing.assert_allclose(rois[1].coordinates()[:, 0], points[3][:, 1] + 0.5, atol=1e-4)
    # float32 storage: 1e-4 px at 500 px
    _assert_same(points, roi.read_points_imagej(path), atol=1e-4)


def test_imagej_single_roi_file(points, tmp_path):
    one = {3: points[3]}
    path = roi.write_points(tmp_path / "f3.roi", one)
    _assert_same(one, roi.read_points(path), atol=1e-4)
    with pytest.raises(ValueError, match="one frame"):
        roi.write_points_imagej(tmp_path / "x.roi", points)


def test_imagej_integer_roi_from_elsewhere(tmp_path):
    """A multi-point ROI drawn in ImageJ with integer coordinates names pixels: no shift."""
    r = roifile.ImagejRoi.frompoints(np.array([[10, 20], [11, 22]], dtype=np.int32), name="membrane")
    r.roitype = roifile.ROI_TYPE.POINT
    r.position = 5  # stack slice 5 -> frame 4
    path = tmp_path / "ij.roi"
    r.tofile(path)
    got = roi.read_points(path)
    assert list(got) == [4]
    np.testing.assert_array_equal(got[4], [[20, 10], [22, 11]])


def test_imagej_frame_from_name_when_no_position(tmp_path):
    r = roifile.ImagejRoi.frompoints(np.array([[1.5, 2.5]]), name="Frame_17")
    r.tofile(tmp_path / "n.roi")
    got = roi.read_points_imagej(tmp_path / "n.roi")
    np.testing.assert_allclose(got[17], [[2.0, 1.0]])


def test_csv_and_imagej_agree(points, tmp_path):
    a = roi.read_points(roi.write_points(tmp_path / "a.csv", points))
    b = roi.read_points(roi.write_points(tmp_path / "b.zip", points))
    _assert_same(a, b, atol=1e-4)


@pytest.mark.parametrize(
    ("name", "kwargs", "match"),
    [
        ("p.txt", {}, r"\.csv, \.zip or \.roi"),
        ("p.zip", {"kind": "oval"}, "kind must be one of"),
        ("p.csv", {"pixel_size_um": -1.0}, "pixel_size_um"),
    ],
)
def test_write_errors(points, tmp_path, name, kwargs, match):
    with pytest.raises(ValueError, match=match):
        roi.write_points(tmp_path / name, points, **kwargs)


def test_write_empty_rejected(tmp_path):
    with pytest.raises(ValueError, match="nothing to write"):
        roi.write_points_imagej(tmp_path / "e.zip", {0: np.empty((0, 2))})
