r"""Readers of micrograph series: lazy frames plus pixel size and timestamps.

A series is

* one multi-page TIFF or OME-TIFF file (``.tif``, ``.tiff``, ``.ome.tif``);
* a folder of single images (TIFF, PNG, JPEG), ordered by their acquisition
  time when every file carries one (TIFF ``DateTime`` tag 306 / EXIF
  ``DateTimeOriginal`` with ``SubSecTime*``), else in natural file-name order
  (``frame2`` before ``frame10``);
* a Zeiss CZI file (read with ``aicspylibczi``);
* or an array of shape (T, H, W) already in memory.

:func:`open_series` returns a :class:`FrameSeries`: a sequence of 2-D numpy
arrays that reads each frame from disk only when it is indexed (tifffile
memory map or page-by-page reads, one file per frame for folders, one
subblock per frame for CZI), so a 10 GB series never sits in memory.

Metadata
--------
The **pixel size** (m) comes from the file when it carries one: OME-XML
``PhysicalSizeX/Y`` with their units; ImageJ's ``unit`` with the resolution
tags; CZI ``Scaling/Items/Distance`` (metres); plain TIFF/PNG/JPEG resolution
tags only with a physical unit (cm, or tifffile's non-standard micrometre unit
5) or an inch resolution above 1000 dpi -- lower dpi values (72, 96, 300...)
are display defaults, never a calibration.  **Timestamps** (s from the first
frame) come from OME ``Plane/DeltaT`` or ``TimeIncrement``, ImageJ
``finterval``, per-file TIFF/EXIF date-times, or CZI subblock
``AcquisitionTime``.  When the file lacks a value it must be passed
(``pixel_size=``, ``frame_interval=`` or ``timestamps=``); when both exist they
must agree within ``rtol``; either failure is a :class:`MetadataError` naming
what to set.

Bad frames
----------
Every frame file is checked when the series is opened without reading its
pixels: a header that does not parse, image data running past the end of the
file (a truncated TIFF, a PNG without its IEND chunk, a JPEG without its end marker), or a frame
whose shape differs from the series' is flagged -- a warning naming the file,
an entry in :attr:`FrameSeries.bad_frames` -- and skipped.  A frame that
still fails when it is read raises :class:`FrameReadError` naming the file (and
is added to ``bad_frames``); :meth:`FrameSeries.iter_frames` skips such
frames.  A path that is not an image series at all is a ``ValueError``.

Colour
------
RGB(A) frames become grey by the ITU-R BT.709 luminance
``0.2126 R + 0.7152 G + 0.0722 B`` (as ``skimage.color.rgb2gray``), computed in
float and rounded back to the input's integer type, so 8-bit stays 8-bit and
16-bit stays 16-bit; alpha is dropped; ``grey="mean"`` or a single channel
(``"red"``, ``"green"``, ``"blue"``) are the alternatives.  Grey frames are
returned as stored (16-bit kept as is).
"""

from __future__ import annotations

import datetime as _dt
import logging
import math
import os
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = [
    "FrameSeries",
    "open_series",
    "read_first_frame",
    "MetadataError",
    "FrameReadError",
    "write_series",
    "write_truth",
    "read_truth",
    "IMAGE_EXTENSIONS",
    "GREY_METHODS",
    "ORDERS",
    "WRITE_FORMATS",
]

IMAGE_EXTENSIONS = (".tif", ".tiff", ".png", ".jpg", ".jpeg")
GREY_METHODS = ("luminance", "mean", "red", "green", "blue")
ORDERS = ("auto", "time", "name")
MISSING_POLICIES = ("raise", "warn")
WRITE_FORMATS = ("tiff", "ome-tiff", "tiff-folder", "png", "jpeg")
#: BT.709 luma weights (skimage.color.rgb2gray)
_LUMA = np.array([0.2125, 0.7154, 0.0721])
_LENGTH_UNITS = {
    "m": 1.0,
    "cm": 1e-2,
    "mm": 1e-3,
    "um": 1e-6,
    "µm": 1e-6,
    "μm": 1e-6,
    "micron": 1e-6,
    "microns": 1e-6,
    "micrometer": 1e-6,
    "micrometre": 1e-6,
    "nm": 1e-9,
    "pm": 1e-12,
    "å": 1e-10,
    "angstrom": 1e-10,
    "\\u00b5m": 1e-6,
}
_TIME_UNITS = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6,
               "min": 60.0, "minute": 60.0, "minutes": 60.0, "h": 3600.0, "hr": 3600.0, "hour": 3600.0,
               "hours": 3600.0, "ns": 1e-9}  # fmt: skip
#: hints naming what to set, used in every metadata error
PIXEL_SIZE_HINT = "pass pixel_size= (m/px) or set [imaging] pixel_size_um in experiment.toml"
TIME_HINT = (
    "pass frame_interval= (s) or timestamps= (s), or set [imaging] frame_interval_min or timestamps_min "
    "in experiment.toml"
)


class MetadataError(ValueError):
    """Pixel size or timestamps missing from the file and the arguments, or in conflict."""


class FrameReadError(ValueError):
    """A frame that passed the header check could not be decoded."""


# --------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------
def _to_grey(a, grey):
    """(H, W[, S]) -> (H, W) in the input's dtype (see module docstring)."""
    a = np.asarray(a)
    if a.ndim == 2:
        return a
    if a.ndim != 3 or a.shape[2] not in (2, 3, 4):
        raise ValueError(f"expected a grey (H, W) or colour (H, W, 3|4) frame, got shape {a.shape}")
    if a.shape[2] == 2:  # grey + alpha
        return a[..., 0]
    rgb = a[..., :3]
    if grey == "luminance":
        g = rgb.astype(np.float64) @ _LUMA
    elif grey == "mean":
        g = rgb.astype(np.float64).mean(axis=2)
    else:
        return np.ascontiguousarray(rgb[..., ("red", "green", "blue").index(grey)])
    if np.issubdtype(a.dtype, np.integer):
        info = np.iinfo(a.dtype)
        return np.clip(np.rint(g), info.min, info.max).astype(a.dtype)
    return g.astype(a.dtype)


def _parse_exif_datetime(text, subsec=None):
    """'YYYY:MM:DD HH:MM:SS' (+ sub-second digits) -> datetime or None."""
    if text is None:
        return None
    if isinstance(text, bytes):
        text = text.decode("ascii", "ignore")
    text = str(text).strip().strip("\x00")
    for fmt in ("%Y:%m:%d %H:%M:%S", "%Y-%m-%d %H:%M:%S", "%Y-%m-%dT%H:%M:%S"):
        try:
            t = _dt.datetime.strptime(text[:19], fmt)
            break
        except ValueError:
            continue
    else:
        try:
            t = _dt.datetime.fromisoformat(text)
        except ValueError:
            return None
        return t.replace(tzinfo=None) if t.tzinfo is None else t.astimezone(_dt.UTC).replace(tzinfo=None)
    if subsec:
        if isinstance(subsec, bytes):
            subsec = subsec.decode("ascii", "ignore")
        digits = "".join(ch for ch in str(subsec) if ch.isdigit())
        if digits:
            t += _dt.timedelta(seconds=float("0." + digits))
    return t


def _length(value, unit, what):
    """Convert a length with a unit string to metres (ValueError naming the unit)."""
    u = str(unit or "µm").strip().lower().replace("micro", "µ") if unit else "µm"
    u = {"µmeter": "µm", "µmetre": "µm", "µn": "µm"}.get(u, u)
    key = u if u in _LENGTH_UNITS else str(unit).strip().lower()
    if key not in _LENGTH_UNITS:
        raise MetadataError(f"{what}: unknown length unit {unit!r}; {PIXEL_SIZE_HINT}")
    return float(value) * _LENGTH_UNITS[key]


def _seconds(value, unit, what):
    u = str(unit or "s").strip().lower()
    if u not in _TIME_UNITS:
        raise MetadataError(f"{what}: unknown time unit {unit!r}; {TIME_HINT}")
    return float(value) * _TIME_UNITS[u]


def _resolution_pixel_size(xres, yres, unit_code):
    """Pixel size (m) from TIFF-style resolution (pixels per unit), or None if not physical."""

    def ratio(r):
        if r is None:
            return None
        if isinstance(r, tuple):
            return r[0] / r[1] if r[1] else None
        return float(r)

    x, y = ratio(xres), ratio(yres)
    if not x or not y or x <= 0 or y <= 0:
        return None
    per_unit = {3: 1e-2, 4: 1e-3, 5: 1e-6}.get(unit_code)  # cm; mm and um (tifffile, non-standard)
    if unit_code == 2:  # inch: only a microscope-like calibration, not a display default
        if x <= 1000 or y <= 1000:
            return None
        per_unit = 0.0254
    if per_unit is None:
        return None
    px, py = per_unit / x, per_unit / y
    if not math.isclose(px, py, rel_tol=1e-3):
        raise MetadataError(f"non-square pixels in the file ({px:.6g} x {py:.6g} m); only square pixels are supported")
    return px


def _natsorted(paths):
    from natsort import natsorted, ns

    return natsorted(paths, key=lambda p: p.name, alg=ns.IGNORECASE)


# --------------------------------------------------------------------------------------
# backends: each provides n, shape, dtype, names, read(i), pixel_size, times (s, absolute or relative)
# --------------------------------------------------------------------------------------
class _ArrayBackend:
    kind = "array"

    def __init__(self, arr, grey):
        a = np.asarray(arr) if not hasattr(arr, "__array_function__") else arr
        if a.ndim == 2:
            a = a[None]
        elif a.ndim == 4 and a.shape[-1] in (3, 4):
            pass
        elif a.ndim != 3:
            raise ValueError(f"an array series must have shape (T, H, W) or (T, H, W, 3|4), got {a.shape}")
        self.arr, self.grey = a, grey
        self.n = a.shape[0]
        self.frame_shape = tuple(a.shape[1:3])
        self.dtype = np.dtype(a.dtype)
        self.names = [f"frame {i}" for i in range(self.n)]
        self.pixel_size, self.times, self.time_resolution, self.bad = None, None, 0.0, []
        self.source = "<array>"

    def read(self, i, copy=True):  # noqa: ARG002 - frames of an array are views of it either way
        return _to_grey(np.asarray(self.arr[i]), self.grey)

    def close(self):
        pass


class _TiffBackend:
    """One multi-page TIFF / OME-TIFF / ImageJ hyperstack."""

    kind = "tiff"

    def __init__(self, path, grey, channel):
        import tifffile

        self.path, self.grey = Path(path), grey
        self.source = str(self.path)
        log = logging.getLogger("tifffile")
        level = log.level
        log.setLevel(logging.CRITICAL)  # damage is reported as bad frames below, not as log noise
        try:
            self.tif = tifffile.TiffFile(self.path)
            _ = self.tif.series
        except Exception as err:  # not a TIFF at all
            raise ValueError(f"{self.path} is not a readable TIFF image ({err})") from err
        finally:
            log.setLevel(level)
        try:
            self._setup(channel)
        except Exception:
            self.tif.close()
            raise

    def _setup(self, channel):
        tif = self.tif
        if not tif.series:
            raise ValueError(f"{self.path} holds no image series")
        series = tif.series[0]
        self.kind = "ome-tiff" if tif.is_ome else ("imagej-tiff" if tif.is_imagej else "tiff")
        axes, shape = series.axes, series.shape
        spatial = [ax for ax in axes if ax in "YXS"]
        if spatial[:2] != ["Y", "X"]:
            hint = ""
            n_s = shape[axes.index("S")] if "S" in axes else 0
            if axes.endswith("SYX") and n_s in (3, 4):
                # tifffile.imwrite of a (3 or 4, H, W) stack stores one planar RGB(A) page, not 3 or 4 frames
                hint = (f" -- {n_s} planar colour samples in one page; a stack of {n_s} frames saved with "
                        f"tifffile.imwrite needs photometric='minisblack'")
            raise ValueError(f"{self.path}: unsupported axes {axes!r} (need ...YX or ...YXS){hint}")
        lead = [(ax, n) for ax, n in zip(axes, shape, strict=True) if ax not in "YXS"]
        pages = list(series.pages)
        if not (tif.is_ome or tif.is_imagej) and len(tif.series) > 1:
            # frames appended one write at a time: every full-size page is a frame
            first = tif.pages[0]
            pages = [
                pg
                for pg in tif.pages
                if tuple(pg.shape) == tuple(first.shape)
                and pg.dtype == first.dtype
                and not getattr(pg, "is_reduced", False)
            ]
            lead = [("I", len(pages))]
            axes = "I" + "".join(spatial)
            shape = (len(pages), *first.shape)
        n_pages = int(np.prod([n for _, n in lead])) if lead else 1
        if len(pages) != n_pages:  # pages missing (e.g. a truncated file): keep what is there
            pages = pages[:n_pages]
        idx = np.arange(n_pages).reshape([n for _, n in lead] or [1])
        lead_axes = [ax for ax, _ in lead]
        if "C" in lead_axes and shape[axes.index("C")] > 1:
            nc = shape[axes.index("C")]
            if channel is None:
                raise ValueError(f"{self.path} has {nc} channels: pass channel= (0..{nc - 1})")
            if not 0 <= int(channel) < nc:
                raise ValueError(f"channel={channel!r} out of range 0..{nc - 1} for {self.path}")
            idx = np.take(idx, int(channel), axis=lead_axes.index("C"))
            lead_axes.remove("C")
        self.channel = int(channel) if channel is not None else 0
        self.page_index = idx.ravel()
        self.frame_axes = "".join(lead_axes)
        self.pages = pages
        size = self.path.stat().st_size
        self.bad = []
        self._contiguous = None
        if self._chain_truncated():
            n_ij = int((tif.imagej_metadata or {}).get("images", 0)) if tif.is_imagej else 0
            if n_ij > self.page_index.size and len(pages) and pages[0].dataoffsets:
                # an ImageJ stack stores its frames back to back: recover every complete one
                self._setup_imagej_contiguous(n_ij, size)
                return
            self.bad.append(
                (f"{self.path.name}[{len(tif.pages)}:]", "file truncated: the pages after this one are lost")
            )
        good = []
        for k, pi in enumerate(self.page_index):
            name = f"{self.path.name}[{k}]"
            if pi >= len(pages) or pages[pi] is None:
                self.bad.append((name, "page missing (file truncated?)"))
                continue
            pg = pages[pi]
            offs = getattr(pg, "dataoffsets", ())
            cnts = getattr(pg, "databytecounts", ())
            if any(o + c > size for o, c in zip(offs, cnts, strict=False)) or not offs:
                self.bad.append((name, "image data run past the end of the file (truncated)"))
                continue
            good.append(k)
        self.good = np.asarray(good, int)
        self.n = self.good.size
        first = pages[self.page_index[self.good[0]]] if self.n else pages[0]
        self.frame_shape = tuple(first.shape[:2])
        self.dtype = np.dtype(first.dtype)
        self.names = [f"{self.path.name}[{k}]" for k in self.good]
        self._memmap = None
        if not self.bad and n_pages == len(pages) and len(tif.series) == 1:
            try:
                import tifffile

                mm = tifffile.memmap(self.path, mode="r")
                if mm.shape[-2:] == self.frame_shape or (mm.ndim >= 3 and mm.shape[-3:-1] == self.frame_shape):
                    # a plain ndarray view of the map: indexing a frame skips np.memmap's subclass bookkeeping
                    self._memmap = np.asarray(mm).reshape((n_pages, *first.shape))
            except (ValueError, OSError):  # compressed or not contiguous: page by page
                self._memmap = None
        self.pixel_size, self.times, self.time_resolution = self._metadata()

    def _chain_truncated(self):
        """True when the last page's next-IFD pointer points past the end of the file."""
        tif = self.tif
        last = tif.pages[-1] if len(tif.pages) else None
        if last is None:
            return False
        fh = tif.filehandle
        size = fh.size
        big = tif.is_bigtiff
        count_size, entry, ptr_fmt = (8, 20, "Q") if big else (2, 12, "I")
        try:
            fh.seek(last.offset)
            n_tags = int(np.frombuffer(fh.read(count_size), tif.byteorder + ("u8" if big else "u2"))[0])
            fh.seek(last.offset + count_size + n_tags * entry)
            raw = fh.read(8 if big else 4)
        except (OSError, ValueError, IndexError):
            return True
        if len(raw) < (8 if big else 4):
            return True
        nxt = int(np.frombuffer(raw, tif.byteorder + ("u8" if ptr_fmt == "Q" else "u4"))[0])
        return nxt != 0 and nxt >= size

    def _setup_imagej_contiguous(self, n_img, size):
        first = self.pages[0]
        shape = tuple(first.shape)
        dtype = np.dtype(first.dtype).newbyteorder(self.tif.byteorder)
        fbytes = int(np.prod(shape)) * dtype.itemsize
        off = int(first.dataoffsets[0])
        n_ok = max(0, min(n_img, (size - off) // fbytes))
        for k in range(n_ok, n_img):
            self.bad.append((f"{self.path.name}[{k}]", "image data run past the end of the file (truncated)"))
        self._contiguous = np.asarray(np.memmap(self.path, dtype=dtype, mode="r", offset=off, shape=(n_ok, *shape)))
        self._memmap = None
        self.page_index = np.arange(n_img)
        self.good = np.arange(n_ok)
        self.n = n_ok
        self.frame_shape = shape[:2]
        self.dtype = np.dtype(first.dtype)
        self.names = [f"{self.path.name}[{k}]" for k in self.good]
        self.pixel_size, self.times, self.time_resolution = self._metadata()

    def _metadata(self):
        import tifffile

        tif = self.tif
        px, times, res = None, None, 0.0
        if tif.is_ome:
            meta = tifffile.xml2dict(tif.ome_metadata)
            image = meta["OME"]["Image"]
            image = image[0] if isinstance(image, list) else image
            pix = image["Pixels"]
            if "PhysicalSizeX" in pix:
                px = _length(pix["PhysicalSizeX"], pix.get("PhysicalSizeXUnit"), "OME PhysicalSizeX")
                py = _length(pix.get("PhysicalSizeY", pix["PhysicalSizeX"]), pix.get("PhysicalSizeYUnit"), "Y")
                if not math.isclose(px, py, rel_tol=1e-3):
                    raise MetadataError(f"non-square pixels in {self.path} ({px:.6g} x {py:.6g} m)")
            planes = pix.get("Plane")
            if planes:
                planes = planes if isinstance(planes, list) else [planes]
                sel = [
                    p
                    for p in planes
                    if int(p.get("TheZ", 0)) == 0 and int(p.get("TheC", 0)) == self.channel and "DeltaT" in p
                ]
                n_t = len(self.page_index)
                if len(sel) >= n_t:
                    sel.sort(key=lambda p: int(p.get("TheT", 0)))
                    times = np.array([_seconds(p["DeltaT"], p.get("DeltaTUnit"), "OME DeltaT") for p in sel[:n_t]])
            if times is None and "TimeIncrement" in pix:
                dt = _seconds(pix["TimeIncrement"], pix.get("TimeIncrementUnit"), "OME TimeIncrement")
                times = np.arange(len(self.page_index)) * dt
        elif tif.is_imagej:
            ij = tif.imagej_metadata or {}
            page = tif.pages[0]
            unit = ij.get("unit")
            xr = page.tags.get("XResolution")
            yr = page.tags.get("YResolution")
            if unit and xr is not None:
                try:
                    scale = _length(1.0, unit, "ImageJ unit")
                except MetadataError:
                    scale = None
                if scale is not None:
                    xv, yv = xr.value, (yr.value if yr is not None else xr.value)
                    x = xv[0] / xv[1]
                    y = yv[0] / yv[1]
                    if x > 0 and y > 0:
                        px = scale / x
                        if not math.isclose(px, scale / y, rel_tol=1e-3):
                            raise MetadataError(f"non-square pixels in {self.path}")
            if ij.get("finterval"):
                times = np.arange(len(self.page_index)) * _seconds(ij["finterval"], ij.get("tunit", "s"), "finterval")
        else:
            page = tif.pages[0]
            xr, yr, ru = (page.tags.get(k) for k in ("XResolution", "YResolution", "ResolutionUnit"))
            if xr is not None and yr is not None:
                px = _resolution_pixel_size(xr.value, yr.value, int(ru.value) if ru is not None else 2)
        if times is None:  # per-page DateTime tags
            stamps = []
            for k in self.page_index:
                pg = self.pages[k] if k < len(self.pages) else None
                tags = getattr(pg, "tags", None)
                t = None
                if tags is not None and "DateTime" in tags:
                    sub = tags.get(37520)
                    t = _parse_exif_datetime(tags["DateTime"].value, sub.value if sub is not None else None)
                stamps.append(t)
            if stamps and all(s is not None for s in stamps) and len(set(stamps)) > 1:
                t0 = stamps[0]
                times = np.array([(s - t0).total_seconds() for s in stamps])
                res = 1.0
        if times is not None:
            times = np.asarray(times, float)[self.good]
        return px, times, res

    def read(self, i, copy=True):
        k = self.good[i]
        pi = self.page_index[k]
        try:
            if self._contiguous is not None:
                a = np.array(self._contiguous[pi], copy=copy)
            elif self._memmap is not None:
                a = np.array(self._memmap[pi], copy=copy)
            else:
                pg = self.pages[pi]
                a = pg.asarray()
                pg.__dict__.pop("decode", None)  # tifffile caches a decoder closure per page: keep memory flat
        except Exception as err:
            raise FrameReadError(f"cannot decode {self.names[i]}: {err}") from err
        return _to_grey(a, self.grey)

    def close(self):
        self._memmap = None
        self._contiguous = None
        self.tif.close()


def _probe_image_file(path, grey):
    """Header of one frame file: (shape (H, W), dtype, datetime or None, pixel size or None)."""
    suffix = path.suffix.lower()
    size = path.stat().st_size
    if suffix in (".tif", ".tiff"):
        import tifffile

        with tifffile.TiffFile(path) as tif:
            pg = tif.pages[0]
            offs, cnts = pg.dataoffsets, pg.databytecounts
            if not offs or any(o + c > size for o, c in zip(offs, cnts, strict=False)):
                raise ValueError("image data run past the end of the file (truncated)")
            shape = tuple(pg.shape[:2])
            dtype = np.dtype(pg.dtype)
            tags = pg.tags
            stamp = None
            exif = tags.get("ExifTag")
            exif = exif.value if exif is not None and isinstance(exif.value, dict) else {}
            for key, subkey in (
                ("DateTimeOriginal", "SubsecTimeOriginal"),
                ("DateTimeDigitized", "SubsecTimeDigitized"),
            ):
                if key in exif:
                    stamp = _parse_exif_datetime(exif[key], exif.get(subkey))
                    break
            if stamp is None and "DateTime" in tags:
                sub = tags.get(37520)
                stamp = _parse_exif_datetime(tags["DateTime"].value, sub.value if sub is not None else None)
            xr, yr, ru = (tags.get(k) for k in ("XResolution", "YResolution", "ResolutionUnit"))
            px = None
            if xr is not None and yr is not None:
                px = _resolution_pixel_size(xr.value, yr.value, int(ru.value) if ru is not None else 2)
            return shape, dtype, stamp, px
    from PIL import Image

    if suffix in (".jpg", ".jpeg"):
        with open(path, "rb") as fh:
            fh.seek(max(0, size - 64))
            if b"\xff\xd9" not in fh.read():
                raise ValueError("JPEG end-of-image marker missing (file truncated)")
    with Image.open(path) as im:
        if im.format not in ("PNG", "JPEG", "MPO"):
            raise ValueError(f"unexpected image format {im.format}")
        mode = im.mode
        w, h = im.size
        exif = im.getexif()
        stamp = None
        sub_ifd = exif.get_ifd(0x8769) if exif else {}
        if 36867 in sub_ifd:
            stamp = _parse_exif_datetime(sub_ifd[36867], sub_ifd.get(37521))
        elif 306 in exif:
            stamp = _parse_exif_datetime(exif[306], sub_ifd.get(37520))
        elif "Creation Time" in im.info:
            stamp = _parse_exif_datetime(im.info["Creation Time"])
        dpi = im.info.get("dpi")
        px = _resolution_pixel_size(dpi[0], dpi[1], 2) if dpi else None
    if suffix == ".png":  # a complete PNG ends with its IEND chunk (cheap: no pixel data read)
        with open(path, "rb") as fh:
            fh.seek(max(0, size - 12))
            if fh.read()[-8:] != b"IEND\xaeB`\x82":
                raise ValueError("PNG IEND chunk missing (file truncated)")
    dtype = {"I;16": np.uint16, "I;16B": np.uint16, "I;16L": np.uint16, "I": np.int32, "F": np.float32}.get(
        mode, np.uint8
    )
    return (h, w), np.dtype(dtype), stamp, px


def _read_pil(path, grey):
    from PIL import Image

    with Image.open(path) as im:
        if im.mode == "P":
            im = im.convert("RGBA" if "transparency" in im.info else "RGB")
        elif im.mode == "CMYK":
            im = im.convert("RGB")
        elif im.mode == "I;16B":
            im = im.convert("I;16")
        a = np.asarray(im)
    return _to_grey(a, grey)


class _FolderBackend:
    kind = "folder"

    def __init__(self, folder, grey, order, files=None):
        """A folder of single-frame images, or an explicit list of such files (e.g. a glob's matches)."""
        self.grey = grey
        if files is None:
            self.folder = Path(folder)
            self.source = str(self.folder)
            files = [
                p
                for p in self.folder.iterdir()
                if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in IMAGE_EXTENSIONS
            ]
            if not files:
                raise ValueError(f"{self.folder} holds no image files ({', '.join(IMAGE_EXTENSIONS)})")
        else:
            files = [Path(f) for f in files]
            for f in files:
                if not f.is_file():
                    raise FileNotFoundError(f"no such image file: {f}")
            self.folder = Path(os.path.commonpath([str(f.parent) for f in files]))
            self.source = f"{len(files)} files in {self.folder}"
        files = _natsorted(files)
        self.bad = []
        probes = []
        for p in files:
            try:
                probes.append((p, *_probe_image_file(p, grey)))
            except Exception as err:  # noqa: BLE001 - any failure flags the frame
                self.bad.append((p.name, f"unreadable: {err}"))
        if not probes:
            raise ValueError(f"no readable image in {self.folder}: " + "; ".join(f"{n}: {r}" for n, r in self.bad))
        # the series' frame shape is the most common one
        shapes = [pr[1] for pr in probes]
        ref_shape = max(set(shapes), key=shapes.count)
        kept = []
        for pr in probes:
            if pr[1] != ref_shape:
                self.bad.append((pr[0].name, f"shape {pr[1]} differs from the series' {ref_shape}"))
            else:
                kept.append(pr)
        stamps = [pr[3] for pr in kept]
        have_time = all(s is not None for s in stamps) and len(set(stamps)) > 1
        if order == "time" and not have_time:
            raise MetadataError(
                f"order='time' needs an acquisition time in every file of {self.folder} "
                "(TIFF DateTime / EXIF DateTimeOriginal); use order='name'"
            )
        if order in ("auto", "time") and have_time:
            rank = {id(pr): k for k, pr in enumerate(kept)}
            kept.sort(key=lambda pr: (pr[3], rank[id(pr)]))
            stamps = [pr[3] for pr in kept]
        self.files = [pr[0] for pr in kept]
        self.names = [p.name for p in self.files]
        self.n = len(kept)
        self.frame_shape = ref_shape
        self.dtype = kept[0][2]
        self.times, self.time_resolution = None, 0.0
        if have_time:
            t0 = stamps[0]
            self.times = np.array([(s - t0).total_seconds() for s in stamps])
            self.time_resolution = 0.0 if any(s.microsecond for s in stamps) else 1.0
            self.start_time = t0.isoformat()
        pxs = [pr[4] for pr in kept]
        self.pixel_size = None
        if all(p is not None for p in pxs):
            if max(pxs) > min(pxs) * (1 + 1e-3):
                raise MetadataError(
                    f"the files of {self.folder} disagree on the pixel size ({min(pxs):.6g}..{max(pxs):.6g} m)"
                )
            self.pixel_size = float(np.median(pxs))

    def read(self, i, copy=True):  # noqa: ARG002 - each file is decoded into a new array
        p = self.files[i]
        try:
            if p.suffix.lower() in (".tif", ".tiff"):
                import tifffile

                a = _to_grey(tifffile.imread(p, key=0), self.grey)
            else:
                a = _read_pil(p, self.grey)
        except Exception as err:
            raise FrameReadError(f"cannot decode {p.name}: {err}") from err
        if a.shape != self.frame_shape:
            raise FrameReadError(f"{p.name} has shape {a.shape}, the series {self.frame_shape}")
        return a

    def close(self):
        pass


class _CziBackend:
    kind = "czi"

    def __init__(self, path, grey, channel):
        try:
            from aicspylibczi import CziFile
        except ImportError as err:  # pragma: no cover - optional dependency
            raise ImportError("reading CZI needs aicspylibczi: pip install 'osmobulge[czi]'") from err
        self.path, self.grey = Path(path), grey
        self.source = str(self.path)
        try:
            self.czi = CziFile(str(self.path))
            dims = self.czi.get_dims_shape()[0]
        except Exception as err:
            raise ValueError(f"{self.path} is not a readable CZI file ({err})") from err
        try:
            self._setup(dims, channel)
        except Exception:
            self.close()
            raise

    def _setup(self, dims, channel):
        if self.czi.is_mosaic():
            raise ValueError(f"{self.path} is a tiled mosaic; stitch it in ZEN and export the time series")
        self.dims = dims
        nt = dims.get("T", (0, 1))[1] - dims.get("T", (0, 1))[0]
        nc = dims.get("C", (0, 1))[1] - dims.get("C", (0, 1))[0]
        nz = dims.get("Z", (0, 1))[1] - dims.get("Z", (0, 1))[0]
        if nc > 1 and channel is None:
            raise ValueError(f"{self.path} has {nc} channels: pass channel= (0..{nc - 1})")
        if nz > 1:
            raise ValueError(f"{self.path} is a z-stack ({nz} planes): export one plane per time point")
        self.channel = int(channel or 0)
        self.n = nt
        self.t0 = dims.get("T", (0, 1))[0]
        self.names = [f"{self.path.name}[T={k}]" for k in range(nt)]
        self.bad = []
        pt = self.czi.pixel_type.lower()
        self.dtype = np.dtype({"gray8": np.uint8, "gray16": np.uint16, "gray32float": np.float32, "bgr24": np.uint8,
                               "bgr48": np.uint16}.get(pt, np.uint16))  # fmt: skip
        self.bgr = pt.startswith("bgr")
        self.frame_shape = (dims["Y"][1] - dims["Y"][0], dims["X"][1] - dims["X"][0])
        self.pixel_size, self.times, self.time_resolution = self._metadata()

    def _metadata(self):
        meta = self.czi.meta
        px = None
        vals = {}
        for d in meta.iter("Distance"):
            v = d.find("Value")
            if d.get("Id") in ("X", "Y") and v is not None and v.text:
                vals[d.get("Id")] = float(v.text)
        if vals.get("X", 0) > 0:
            x = vals["X"]
            if x > 1e-3:  # CZI stores metres; a larger value was written in um by a non-conforming writer
                warnings.warn(
                    f"{self.path}: CZI Scaling X = {x} is not plausible in metres; reading it as um",
                    UserWarning,
                    stacklevel=4,
                )
                x *= 1e-6
                vals["Y"] = vals.get("Y", x * 1e6) * 1e-6
            px = x
            if "Y" in vals and vals["Y"] > 0 and not math.isclose(vals["Y"], x, rel_tol=1e-3):
                raise MetadataError(f"non-square pixels in {self.path}")
        times = None
        stamps = []
        for k in range(self.n):
            try:
                sb = self.czi.read_subblock_metadata(T=self.t0 + k, C=self.channel)
                text = sb[0][1] if sb else ""
            except Exception:  # noqa: BLE001 - metadata only
                text = ""
            t = None
            i = text.find("<AcquisitionTime>")
            if i >= 0:
                j = text.find("</AcquisitionTime>", i)
                t = _parse_exif_datetime(text[i + 17 : j])
            stamps.append(t)
        if stamps and all(s is not None for s in stamps):
            times = np.array([(s - stamps[0]).total_seconds() for s in stamps])
        return px, times, 0.0

    def read(self, i, copy=True):  # noqa: ARG002 - each frame is decoded into a new array
        try:
            img, _ = self.czi.read_image(T=self.t0 + i, C=self.channel)
        except Exception as err:
            raise FrameReadError(f"cannot decode {self.names[i]}: {err}") from err
        a = np.asarray(img)
        if self.bgr:
            a = a.reshape(*a.shape[-3:])[..., ::-1]
            return _to_grey(a, self.grey)
        return a.reshape(a.shape[-2:])

    def close(self):
        fh = getattr(self.czi, "_bytes", None)  # aicspylibczi keeps the file object here
        if hasattr(fh, "close"):
            fh.close()


# --------------------------------------------------------------------------------------
# the public series object
# --------------------------------------------------------------------------------------
class FrameSeries(Sequence):
    """A lazily read series of 2-D frames with pixel size and timestamps.

    Obtain it from :func:`open_series`.  Indexing reads one frame
    (``series[i]`` -> ndarray of shape (H, W)); slicing returns a lazy
    sub-series.  Use as a context manager (or call :meth:`close`) to release
    file handles.

    Attributes
    ----------
    source : str
        The path (or ``"<array>"``).
    kind : str
        "tiff", "ome-tiff", "imagej-tiff", "folder", "czi" or "array".
    shape : tuple of int
        (T, H, W).
    dtype : numpy.dtype
        Frame type (after colour -> grey).
    pixel_size : float or nan, m
        Square pixel size.
    timestamps : ndarray of shape (T,), s
        Acquisition times from the first frame (NaN where unknown).
    names : list of str
        File name (with page index for multi-frame files) of every frame.
    bad_frames : list of (str, str)
        Frames skipped or failing, with the reason.
    metadata_source : dict
        Where the pixel size and timestamps came from ("file" or "argument").
    """

    def __init__(self, backend, index, pixel_size, timestamps, metadata_source, start_time=""):
        self._b = backend
        self._index = np.asarray(index, int)
        self.pixel_size = pixel_size
        self.timestamps = timestamps
        self.metadata_source = metadata_source
        self.start_time = start_time

    # -- sequence protocol ------------------------------------------------------------
    def __len__(self):
        return int(self._index.size)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return FrameSeries(
                self._b, self._index[i], self.pixel_size, self.timestamps[i], self.metadata_source, self.start_time
            )
        if isinstance(i, (list, np.ndarray)):
            idx = np.asarray(i)
            if idx.dtype == bool:
                idx = np.flatnonzero(idx)
            return FrameSeries(
                self._b, self._index[idx], self.pixel_size, self.timestamps[idx], self.metadata_source, self.start_time
            )
        try:
            k = int(i)
        except TypeError:
            raise TypeError(f"frame index must be an int or a slice, got {type(i).__name__}") from None
        return self._read(k, True)

    def peek(self, i):
        """Frame ``i`` like ``series[i]``, but without a copy where the file is memory-mapped.

        An uncompressed TIFF's frame is then a read-only view of the mapped file:
        only the pages a caller touches are read (the extraction samples a few
        percent of each frame), and it is valid only while the series is open.
        Other sources return their copy as ``series[i]`` does.
        """
        return self._read(int(i), False)

    def _read(self, k, copy):
        n = len(self)
        if not -n <= k < n:
            raise IndexError(f"frame index {k} out of range for a series of {n} frames")
        j = int(self._index[k])
        try:
            return self._b.read(j, copy=copy)
        except FrameReadError as err:
            entry = (self._b.names[j], str(err))
            if entry not in self._b.bad:
                self._b.bad.append(entry)
            raise

    def iter_frames(self):
        """Yield ``(index, frame)`` for every frame that decodes, warning about the others.

        Frames failing here are added to :attr:`bad_frames` and skipped.
        """
        for k in range(len(self)):
            try:
                yield k, self[k]
            except FrameReadError as err:
                warnings.warn(f"skipping frame {k}: {err}", UserWarning, stacklevel=2)

    # -- properties -------------------------------------------------------------------
    @property
    def shape(self):
        return (len(self), *self._b.frame_shape)

    @property
    def dtype(self):
        return self._b.dtype

    @property
    def names(self):
        return [self._b.names[j] for j in self._index]

    @property
    def bad_frames(self):
        return list(self._b.bad)

    @property
    def source(self):
        return self._b.source

    @property
    def kind(self):
        return self._b.kind

    @property
    def frame_interval(self):
        """Median time between frames (s), NaN with fewer than 2 timed frames."""
        t = np.asarray(self.timestamps, float)
        return float(np.nanmedian(np.diff(t))) if t.size > 1 and np.isfinite(t).sum() > 1 else math.nan

    def to_dask(self):
        """A lazy ``dask.array`` of shape (T, H, W), one chunk per frame."""
        import dask
        import dask.array as da

        h, w = self._b.frame_shape
        read = dask.delayed(self._b.read, pure=True)
        parts = [da.from_delayed(read(int(j)), shape=(h, w), dtype=self.dtype) for j in self._index]
        return da.stack(parts) if parts else da.zeros((0, h, w), dtype=self.dtype)

    def attrs(self) -> dict:
        """netCDF-safe description of the series for Dataset attrs."""
        return {
            "source": self.source,
            "source_kind": self.kind,
            "pixel_size": float(self.pixel_size) if self.pixel_size is not None else math.nan,
            "pixel_size_source": self.metadata_source.get("pixel_size", "none"),
            "time_source": self.metadata_source.get("timestamps", "none"),
            "start_time": self.start_time or "unknown",
            "bad_frames": "; ".join(f"{n}: {r}" for n, r in self.bad_frames) or "none",
        }

    def close(self):
        """Release file handles."""
        self._b.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        px = f"{self.pixel_size * 1e6:.4g} um/px" if self.pixel_size and math.isfinite(self.pixel_size) else "?"
        return f"<FrameSeries {self.kind} {self.shape} {self.dtype} {px} from {self.source!r}>"


def _backend_for(source, grey, order, channel):
    if isinstance(source, list | tuple) and source and all(isinstance(f, str | os.PathLike) for f in source):
        # a list of files (e.g. the matches of a frames glob): one frame per file, natural order
        if len(source) == 1:
            return _backend_for(source[0], grey, order, channel)
        return _FolderBackend(None, grey, order, files=source)
    if not isinstance(source, (str, os.PathLike)):
        return _ArrayBackend(source, grey)
    path = Path(source)
    if not path.exists():
        raise FileNotFoundError(f"no such file or folder: {path}")
    if path.is_dir():
        return _FolderBackend(path, grey, order)
    suffix = path.suffix.lower()
    if suffix == ".czi":
        return _CziBackend(path, grey, channel)
    if suffix in (".tif", ".tiff", ".btf", ".tf8"):
        return _TiffBackend(path, grey, channel)
    if suffix in (".png", ".jpg", ".jpeg"):
        # one image: a folder backend restricted to that file
        b = _FolderBackend.__new__(_FolderBackend)
        b.folder, b.grey, b.source = path.parent, grey, str(path)
        try:
            shape, dtype, stamp, px = _probe_image_file(path, grey)
        except Exception as err:  # noqa: BLE001
            raise ValueError(f"{path} is not a readable image ({err})") from err
        b.files, b.names, b.n, b.frame_shape, b.dtype = [path], [path.name], 1, shape, dtype
        b.bad, b.times, b.time_resolution, b.pixel_size = [], None, 0.0, px
        return b
    with open(path, "rb") as fh:
        head = fh.read(8)
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return _TiffBackend(path, grey, channel)
    if head[:8] == b"ZISRAWFI":
        return _CziBackend(path, grey, channel)
    raise ValueError(
        f"{path} is not an image series: expected a multi-page TIFF/OME-TIFF, a CZI file or a folder of "
        f"{', '.join(IMAGE_EXTENSIONS)} images"
    )


def open_series(
    source,
    *,
    pixel_size=None,
    frame_interval=None,
    timestamps=None,
    order="auto",
    grey="luminance",
    channel=None,
    rtol=1e-3,
    missing="raise",
) -> FrameSeries:
    """Open a micrograph series lazily, with its pixel size and timestamps.

    Parameters
    ----------
    source : str, Path, sequence of paths, or ndarray of shape (T, H, W)
        A multi-page TIFF/OME-TIFF, a CZI file, a folder of TIFF/PNG/JPEG
        images, one image file, or frames in memory.
    pixel_size : float, optional, m/px
        Used when the file has none; checked against the file's otherwise.
    frame_interval : float, optional, s
        Time between frames, used when the file has no timestamps; checked
        against the file's median interval otherwise.
    timestamps : array_like of shape (T,), optional, s
        Explicit acquisition times (instead of ``frame_interval``).
    order : {"auto", "time", "name"}
        Folder order: by acquisition time when every file has one ("auto")
        or always ("time", an error when some lack it), or natural file-name
        order ("name").
    grey : {"luminance", "mean", "red", "green", "blue"}
        Colour to grey conversion (see the module docstring).
    channel : int, optional
        Channel of a multi-channel TIFF/OME-TIFF/CZI (required when it has several).
    rtol : float
        Relative tolerance of the agreement between file and argument values.
    missing : {"raise", "warn"}
        A missing pixel size or time base raises :class:`MetadataError`, or
        warns and leaves NaN.

    Returns
    -------
    FrameSeries

    Raises
    ------
    MetadataError
        Missing or conflicting pixel size / timestamps; the message names what to set.
    ValueError
        A path that is not an image series, or a bad option.
    """
    if order not in ORDERS:
        raise ValueError(f"order must be one of {ORDERS}, got {order!r}")
    if grey not in GREY_METHODS:
        raise ValueError(f"grey must be one of {GREY_METHODS}, got {grey!r}")
    if missing not in MISSING_POLICIES:
        raise ValueError(f"missing must be one of {MISSING_POLICIES}, got {missing!r}")
    if not (isinstance(rtol, int | float) and 0 < rtol < 1):
        raise ValueError(f"rtol must be in (0, 1), got {rtol!r}")
    if frame_interval is not None and timestamps is not None:
        raise ValueError("pass frame_interval= or timestamps=, not both")
    backend = _backend_for(source, grey, order, channel)
    for name, reason in backend.bad:
        warnings.warn(f"skipping bad frame {name}: {reason}", UserWarning, stacklevel=2)
    if backend.n == 0:
        backend.close()
        raise ValueError(f"no readable frame in {backend.source}: " + "; ".join(f"{n}: {r}" for n, r in backend.bad))
    n = backend.n
    src = {}
    try:
        # -- pixel size ----------------------------------------------------------------
        px_file = backend.pixel_size
        if pixel_size is not None:
            pixel_size = float(pixel_size)
            if not (math.isfinite(pixel_size) and 1e-10 < pixel_size < 1e-2):
                raise ValueError(f"pixel_size must be in metres per pixel (1e-10..1e-2), got {pixel_size!r}")
        if px_file is not None and pixel_size is not None and not math.isclose(px_file, pixel_size, rel_tol=rtol):
            raise MetadataError(
                f"pixel size conflict: the file says {px_file:.6g} m/px, pixel_size={pixel_size:.6g} m/px; "
                "drop pixel_size= (or [imaging] pixel_size_um) to use the file's value, or fix it"
            )
        px = px_file if px_file is not None else pixel_size
        src["pixel_size"] = "file" if px_file is not None else ("argument" if pixel_size is not None else "none")
        if px is None:
            msg = f"pixel size not in the metadata of {backend.source}: {PIXEL_SIZE_HINT}"
            if missing == "raise":
                raise MetadataError(msg)
            warnings.warn(msg, UserWarning, stacklevel=2)
            px = math.nan
        # -- timestamps ----------------------------------------------------------------
        t_file = backend.times
        given = None
        if timestamps is not None:
            given = np.asarray(timestamps, float)
            if given.shape != (n,) or not np.all(np.isfinite(given)):
                raise ValueError(f"timestamps must be {n} finite values (s), got shape {given.shape}")
        elif frame_interval is not None:
            dt = float(frame_interval)
            if not (math.isfinite(dt) and dt > 0):
                raise ValueError(f"frame_interval must be > 0 (s), got {frame_interval!r}")
            given = np.arange(n) * dt
        if t_file is not None and given is not None and n > 1:
            tol = max(rtol * float(np.ptp(t_file)), backend.time_resolution)
            fi, gi = t_file - t_file[0], given - given[0]
            if timestamps is None:  # compare intervals: skipped frames leave gaps in the file times
                d_file = float(np.median(np.diff(t_file)))
                if not math.isclose(d_file, float(frame_interval), rel_tol=rtol, abs_tol=backend.time_resolution):
                    raise MetadataError(
                        f"frame interval conflict: the file's timestamps say {d_file:.6g} s, "
                        f"frame_interval={float(frame_interval):.6g} s; drop frame_interval= "
                        "(or [imaging] frame_interval_min) to use the file's times, or fix it"
                    )
            elif np.max(np.abs(fi - gi)) > tol:
                raise MetadataError(
                    "timestamps conflict with the file's acquisition times (max difference "
                    f"{np.max(np.abs(fi - gi)):.6g} s); drop timestamps= to use the file's times"
                )
        if t_file is not None:
            times = np.asarray(t_file, float)
            src["timestamps"] = "file"
        elif given is not None:
            times = given
            src["timestamps"] = "argument"
        else:
            msg = f"timestamps not in the metadata of {backend.source}: {TIME_HINT}"
            if missing == "raise" and n > 1:
                raise MetadataError(msg)
            if n > 1:
                warnings.warn(msg, UserWarning, stacklevel=2)
            times = np.full(n, math.nan) if n > 1 else np.zeros(1)
            src["timestamps"] = "none"
    except Exception:
        backend.close()
        raise
    return FrameSeries(backend, np.arange(n), px, times, src, getattr(backend, "start_time", ""))


# --------------------------------------------------------------------------------------
# writers (synthetic series, tests, exports)
# --------------------------------------------------------------------------------------
_EPOCH = _dt.datetime(2024, 1, 1, 9, 0, 0)


def read_first_frame(source, *, pixel_size=None, grey="luminance", channel=None):
    """The first readable frame of an image, series file or folder, and its pixel size (m, None if not stored).

    No timestamps are needed (unlike :func:`open_series`): for a single
    reference frame, e.g. ``extract(..., reference_frame=path)``.  With
    ``pixel_size`` (m), a file that stores another one (beyond 0.1 %) is a
    :class:`MetadataError` naming both.
    """
    backend = _backend_for(source, grey, "auto", channel)
    try:
        if not backend.n:
            raise ValueError(f"{source} holds no readable frame")
        frame, px = np.asarray(backend.read(0)), backend.pixel_size
    finally:
        getattr(backend, "close", lambda: None)()
    if pixel_size is not None and px is not None and not math.isclose(px, pixel_size, rel_tol=1e-3):
        raise MetadataError(f"{source} has a pixel size of {px:.6g} m, the series {pixel_size:.6g} m: "
                            f"they must be one field of view")
    return frame, px


def write_series(frames, path, *, fmt="tiff", pixel_size, timestamps=None, start=_EPOCH):
    """Write frames with pixel size and acquisition times in the file metadata.

    Parameters
    ----------
    frames : ndarray of shape (T, H, W)
        uint8 or uint16 frames.
    path : str or Path
        Folder (created if missing); the frames file or files go inside.
    fmt : {"tiff", "ome-tiff", "tiff-folder", "png", "jpeg"}
        See :meth:`osmobulge.imaging.synthetic.SyntheticSeries.save`.
    pixel_size : float, m/px
    timestamps : array_like of shape (T,) or None, s
        Acquisition times from ``start`` (default every 600 s).
    start : datetime.datetime
        Acquisition time of the first frame, for per-file date-times.

    Returns
    -------
    pathlib.Path
        The written file (tiff, ome-tiff) or the folder.
    """
    import tifffile

    if fmt not in WRITE_FORMATS:
        raise ValueError(f"fmt must be one of {WRITE_FORMATS}, got {fmt!r}")
    frames = np.asarray(frames)
    if frames.ndim != 3:
        raise ValueError(f"frames must have shape (T, H, W), got {frames.shape}")
    n = frames.shape[0]
    t = np.arange(n) * 600.0 if timestamps is None else np.asarray(timestamps, float)
    if t.shape != (n,):
        raise ValueError(f"timestamps must have shape ({n},), got {t.shape}")
    folder = Path(path)
    folder.mkdir(parents=True, exist_ok=True)
    um = float(pixel_size) * 1e6
    dt = float(np.median(np.diff(t))) if n > 1 else 0.0
    if fmt == "tiff":
        out = folder / "frames.tif"
        tifffile.imwrite(
            out,
            frames,
            imagej=True,
            resolution=(1.0 / um, 1.0 / um),
            metadata={"axes": "TYX", "unit": "um", "finterval": dt},
        )
        return out
    if fmt == "ome-tiff":
        out = folder / "frames.ome.tif"
        tifffile.imwrite(
            out,
            frames,
            ome=True,
            photometric="minisblack",
            metadata={
                "axes": "TYX",
                "PhysicalSizeX": um,
                "PhysicalSizeXUnit": "µm",
                "PhysicalSizeY": um,
                "PhysicalSizeYUnit": "µm",
                "TimeIncrement": dt,
                "TimeIncrementUnit": "s",
                "Plane": {"DeltaT": [float(x) for x in t], "DeltaTUnit": ["s"] * n},
            },
        )
        return out
    ext = {"tiff-folder": ".tif", "png": ".png", "jpeg": ".jpg"}[fmt]
    if fmt == "jpeg" and frames.dtype != np.uint8:
        raise ValueError("JPEG holds 8-bit frames only: render with bit_depth=8 or save as png/tiff")
    for i in range(n):
        stamp = start + _dt.timedelta(seconds=float(t[i]))
        text = stamp.strftime("%Y:%m:%d %H:%M:%S")
        sub = f"{stamp.microsecond:06d}"
        name = folder / f"frame_{i:05d}{ext}"
        if fmt == "tiff-folder":
            tifffile.imwrite(
                name,
                frames[i],
                resolution=(1e4 / um, 1e4 / um),
                resolutionunit="CENTIMETER",
                datetime=text,
                extratags=[(37520, "s", 0, sub, True)],
            )
        else:
            from PIL import Image

            im = Image.fromarray(frames[i])
            exif = Image.Exif()
            exif[306] = text
            ifd = exif.get_ifd(0x8769)
            ifd[36867] = text
            ifd[37521] = sub
            dpi = 0.0254 / float(pixel_size)
            if fmt == "png":
                im.save(name, exif=exif.tobytes(), dpi=(dpi, dpi))
            else:
                im.save(name, exif=exif.tobytes(), quality=95, dpi=(round(dpi), round(dpi)))
    return folder


def write_truth(truth, folder):
    """Write a ground-truth Dataset as ``folder/truth.nc`` (netCDF4 via h5netcdf, atomically)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / "truth.nc"
    tmp = folder / ".truth.nc.tmp"
    truth.to_netcdf(tmp, engine="h5netcdf")
    os.replace(tmp, out)
    return out


def read_truth(folder):
    """Load ``folder/truth.nc`` written by :func:`write_truth` (fully into memory)."""
    import xarray as xr

    with xr.open_dataset(Path(folder) / "truth.nc", engine="h5netcdf") as ds:
        return ds.load()
