r"""Trace a dome seen only by its faces: the look-agnostic route of the tracer (issue 16).

In transmitted bright field a transparent film in water is not a filled band:
what shows it is the light its faces bend out of the objective.  The dome is
then the silhouette of a shell of revolution: a sharp edge at its **outer
face** (outside it the light passes straight), and inside a zone whose width
and sign depend on focus, condenser and the film's index (lensing, fringes).
The walls are silhouettes of the well's cylinder, the flat film two faint face
lines.  :class:`SilhouetteTracer` therefore reads, in each bulge-up frame:

1. **walls and rim** (:func:`osmobulge.imaging._silhouette.find_walls`): the
   top face and the two walls in the first (flat) frame; in later frames the
   same walls within ``settings.max_drift`` px, on their strip of the base only,
   the drift read by phase correlation of the base's row and column profiles
   (walls, well bottom; no dome there) against the first frame's;
2. **the change**: the frame minus the first frame moved by that drift,
   relative to the flat frame's local light (so the flat film, the walls and
   uneven light cancel, and only what moved is left: the dome), sampled along
   transects only (:func:`osmobulge.imaging._kernels.sample_transects`) and
   smoothed along them;
3. **the outer face**: in a tracked frame, along the normals of the last ok
   frame's outer face moved on by its last step (in one pass within 8 px
   where that prediction holds; else a wider first pass, then along the normals
   of the curve it found; a track in doubt is searched instead); else along
   rays from the rim plane's centre.  Walking in from outside, the first
   strong feature (of the dome's own sign; a halo or fringe of the other sign
   is not it) and on its outer flank the steepest rise (sub-pixel) is the
   silhouette edge.  Rays whose edge jumps from its
   neighbours' (another fringe, dust) are dropped and counted; what lies in
   front of the dome in the water (a neighbour's dome whose well is beyond
   the field, a time stamp burned into the frames: :func:`_in_front`) is
   passed over on the rays;
4. **the mid-surface**: the outer face (a smoothing spline through its
   points only) offset inwards by half the film's thickness (incompressible
   film of uniform meridional stretch, :func:`_thickness`; the film over the
   well holds :math:`l_0 \pi R_0^2`, :math:`R_0` the first frame's rim radius),
   then bridged to the rim: the rim is a point of the mid-surface, while the
   outer face meets the top face about :math:`(l/2)\tan(\beta/2)` outside it
   (:math:`\beta` the angle the film leaves the rim at).  To first order in
   :math:`l` the volume between the outer face and the mid-surface is
   :math:`l_0 \pi R_0^2 / 2` whatever the stretch's distribution, so the
   volume does not depend on that assumption;
5. **measures and flags**: volume and area of both halves
   (:func:`osmobulge.imaging.geometry.revolution_measures`) and the quality
   figures of :class:`osmobulge.imaging.trace.FrameTrace`, with two of this route:
   ``edge_jumps`` (fraction of rays whose edge jumped) and ``edge_lost``
   (fraction of rays over the dome without an edge).

The frame must be upright within a pixel over the field (the top face a row),
as the silhouettes are searched row by row; :class:`SilhouetteTracer` refuses a
tilted first frame.  Everything is in pixels of the bulge-up view.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numba import njit
from scipy import ndimage

from osmobulge.imaging._chamber import ROTATIONS, ChamberGeometry, ChamberNotFound, FrameView, Line, Well
from osmobulge.imaging._clipping import clip_level, clip_mask
from osmobulge.imaging._kernels import (
    change_transects,
    longest_run,
    median,
    native_frame,
    outer_edges,
    percentile,
    running_percentile,
    upsample_linear,
)
from osmobulge.imaging._silhouette import MAX_WALL_RMS, FlatMaps, SilhouetteWalls, find_walls, neighbour_walls
from osmobulge.imaging.geometry import revolution_measures, smooth_profile
from osmobulge.imaging.trace import (
    FIELD_MARGIN_PX,
    FrameTrace,
    TraceSettings,
    field_edge_message,
    first_flag,
    manual_curve,
)

__all__ = ["SilhouetteTracer"]

#: angular range of the rays (rad from the rim plane, each side) and their number (every 0.5 degrees, ~3 px
#: apart at a 350 px dome: they only seed the second pass along the normals (_STATION_STEP); on the 21 looks at
#: 9 frames, volumes within 5e-4 of 721 rays', the same flags; a searched frame 93 -> 60 ms)
_RAY_MIN, _N_RAYS = np.radians(1.0), 361
#: samples along a transect (px) and the Gaussian smoothing of the change image (px)
_RAY_STEP, _SMOOTH = 0.5, 0.7
#: samples along a ray of the full search (px): its edges only seed the pass along the normals (every
#: _NORMAL_STEP); on the 21 looks at 9 frames, every frame searched, volumes within 1e-3 of 0.5 px steps', the
#: same flags; a searched frame 56 -> 37 ms
_SEARCH_STEP = 1.0
#: scatter (px) of the smoothing splines of the curves whose normals are sampled (the full search's and the
#: two-pass track's; the one-pass track follows the last frame's outer face, :class:`_Polyline`)
_FIRST_SIGMA = 1.0
#: and at least that of the outer face measured (its points scatter 0.05-0.17 px across it on the 21 looks,
#: :func:`_scatter`: 0.5 let a curve of few knots lie 0.3-0.6 px off a dome's pole at 2 um/px, the smoothing
#: spline's bias where it bends most; noisier points set their own, :func:`_scatter`)
_FACE_SIGMA = 0.25
#: an edge further than this (px) from the running median of its neighbours' is a jump
_JUMP_PX = 3.0
#: a piece of the full search's change with this share of its samples more than _FRONT_L0 film thicknesses outside
#: the dome's face on their rays (outside it at all, for a piece at the field's side edges) is in front of the
#: dome (:func:`_in_front`)
_FRONT_SHARE, _FRONT_L0 = 0.8, 2.0
# a straight stretch of the outer face (:func:`_least_bend`: its least bend over 10 % of its arc, over its mean bend;
# directions along chords of 2 film thicknesses, at least 2 _BEND_CHORD_PX; no word on a dome turning less than
# _BEND_MIN_DEG in all) under _BEND_FLAG flags a frame: a membrane under pressure bends everywhere.  Measured (optics,
# 2026-12-06): a cap torn off the pole leaves a flat top, -0.18..0.005 on 9 such frames, 8 of them read ok before,
# 5 of those 4.0-10.8x the tolerance off (absorbing_band, defocus, no_grey_step; the edge-only looks lose the edge);
# the 647 ok frames of the cached renders (25 looks, the 97-frame day, the 25-frame neighbour renders, 8x the read
# noise, a 2 um/px day to V/V0 12) 0.33 at least (a corner-based figure flagged the last two: a few px of glitch in
# the trace, their volumes right)
_BEND_CHORD_PX = 8.0
_BEND_MIN_DEG = 40.0
_BEND_FLAG = 0.1
#: fraction of rays over the dome whose edge jumped, or that have none, that flags poor_fit
_JUMP_FLAG, _LOST_FLAG = 0.05, 0.10
#: horizontal transects (rows) the change's noise is measured on: on the 21 looks at 9 frames within -4..+7 % of
#: 64 columns' (16 columns: -9..+5 %), in half the time (a row is contiguous in memory, a column strides); their
#: samples every _NOISE_STEP px, every other row's half a px on: the same mix of whole- and half-px positions
#: (whose bilinear samples average two pixels) as every 0.5 px, within -0.7..+2.0 % of it, in half the samples
_NOISE_ROWS, _NOISE_STEP = 12, 1.0
#: ... but at most this factor times the noise on the rows highest above the top face (measured blind on
#: ho_blind_1206e, a dyed liquid: the dome's inside, darker as it grew, over most of the rows raised the noise until
#: the dome's own contrast fell below 10 of it; a sparse series's first dome frame at Vtilde 4 then read flat and ok)
_NOISE_TOP_ROWS, _NOISE_TOP_FACTOR = 3, 1.25
#: reach (px, each side) of the search along the last frame's outer face's normals, and its stations' spacing
#: (px; samples every _RAY_STEP as on the rays)
_TRACK_REACH, _TRACK_STATIONS = 30.0, 4.5
#: station spacing (px) along the outer face for the fine pass (and the one-pass track), and its normals'
#: reach and step (px); within _FOOT_ARC_PX of arc from either foot, where the dome turns into the top face,
#: stations every _FOOT_STEP px (:func:`_station_arcs`).  Against 1.5 px everywhere, on the 7 dense 25-frame
#: looks: the same flags, worst volume error / tolerance lower on all 7 (e.g. edge_dark 0.32 -> 0.27), median
#: within +0.005/-0.013; a tracked frame 12.4 -> 8.2 ms.  (3 px everywhere: the final spline, then through the
#: rim, cut the feet's corner, -0.1 % of the volume; 4.5 px in the middle: no faster)
_STATION_STEP, _NORMAL_REACH, _NORMAL_STEP = 3.0, 8.0, 0.25
_FOOT_STEP, _FOOT_ARC_PX = 1.5, 40.0
#: arc (px) of the running median a one-pass track's edges are compared with (its stations': as the two-pass
#: track's first pass, 9 stations 4.5 px apart)
_ONE_PASS_MEDIAN_PX = 40.0
#: height (px) above the top face below which the outer face's edge is not used (the feet), and the
#: dome height below which a frame is flagged poor_fit (figure low_dome): its edge is mostly feet
_FOOT_PX, _LOW_DOME_PX = 4.0, 8.0
#: largest disagreement between the flat film's two faces' distance in the first frame and the given
#: thickness (px, or this fraction of it) before every frame is flagged poor_fit (figure flat_film): the top
#: face (the mid plane every height is measured from) is then in doubt
_FILM_TOL_PX, _FILM_TOL = 1.0, 0.05
#: the first frame's film over the well must lie on the top face beside the well: its lift (:func:`_flat_lift`, the
#: mean over the rim disc of how far the face's profile in bins of _LIFT_BIN_PX columns lies above the profile beside
#: the well) beyond _FLAT_LIFT_PX px flags every frame poor_fit (figure flat_lift), as its reference is not flat.  A
#: low dome's silhouette fades into the face (a ray just above the top face crosses the dome's elastomer over a chord
#: that shrinks to nothing at its pole), so this reads less than the dome's true layer, the less the lower the dome
#: (measured 2026-12-06, the 12 optics presets' first frame alone: Vtilde 0.002, a 0.5 px layer, one tolerance,
#: 0.15-0.40 px on 9 looks, 0.08 on the 10 and 26 um films, 0.004 at 2 um/px (there a 0.2 px layer); Vtilde 0.003,
#: 0.19-0.25 on the films and the turbid base; Vtilde 0.005, 0.45-1.05, 0.08 at 2 um/px, 0.16 at 0.007), and the
#: flat first frames of 158 cached renders (presets, held-out looks, probes) read -0.06..+0.034 px.  Before: a first
#: frame at Vtilde 0.003-0.005 read flat and ok, 1.5-2.5x the tolerance, and on the halo look at 0.005 frames 1-2
#: too, 1.7x and 1.3x (the dome's sign learned from the old dome's ghost); from 0.01 the flat film's faces
#: (flat_film) or the dome's search (:meth:`SilhouetteTracer._check_flat`) flagged or refused the series, except
#: absorbing_band, frame 0 ok 5x off.  Now every frame of those series is flagged (Vtilde 0.003 and 0.005, 9 frames,
#: the 12 presets), save 2 um/px, whose frame 0 is then within its tolerance (0.6 and 1.0 of it)
_LIFT_BIN_PX, _FLAT_LIFT_PX = 8, 0.15
#: columns beside the walls kept when a later frame's walls are found (their zone is inside the well, the light
#: just outside them 4-12 px out; find_walls looks for them within 20 px of the expected columns)
_WALL_MARGIN = 40
#: columns inside each wall kept with them (find_walls' peak search, 20 px, and its 3-column smoothing)
_WALL_INSIDE = 26
#: rows of the base the walls are followed down, as fractions of the well depth (more rows than
#: find_walls' default, which must also work with a guessed depth)
_STRIP = (0.1, 0.8)
#: the flat frame's specks (dust fixed to the camera) within _SPECK_PX px, plus the drift, of a point are not a
#: dome's face there (:meth:`SilhouetteTracer._clear_of_specks`; measured: 40 specks and drift 1 px a frame flagged
#: every frame touching without this)
_SPECK_PX = 8
#: a dome within _NEAR_PX px of the column half-way to a neighbouring well has its gap to the neighbour's dome
#: measured row by row (:meth:`_gap_rows`), each row's a running median over _GAP_ROWS rows (a speck a few rows
#: high is not a face); the next frame's dome is then searched for up to the middle of that gap on each row
_NEAR_PX, _GAP_ROWS = 20.0, 15
#: with no neighbouring well seen, a neighbour's dome coming in at the field's side edges is looked for on a grid of
#: _SIDE_STEP px over the water above the top face (:meth:`SilhouetteTracer._side_gap`)
_SIDE_STEP = 2.0
#: a frame whose base is more than _GAIN_TOL brighter or darker than the first frame's (the lamp, the exposure) is
#: divided by that ratio first
_GAIN_TOL = 0.05
#: the light's change across the view since the first frame (a lamp or a window warming one side of the field):
#: a plane fitted to the water's change (:func:`_light_plane`, on ``_TILT_BINS`` bins of columns a noise row)
#: divided out of the change when it raised the noise more than ``_TILT_NOISE`` times
_TILT_BINS, _TILT_NOISE = 16, 1.25
#: in a frame whose base's rows (its light's gain read on them) hold clipped light, the plane through the water's
#: change is also divided out when its level over the water, and the change of the rows highest above the top face,
#: stand more than _LEVEL_NOISE times the noise off 0 (a change of the whole view's light the base's gain did not
#: take off, which the noise, a MAD, does not see: :meth:`SilhouetteTracer._noise`)
_LEVEL_NOISE = 2.0
#: a frame without a dome edge is flat only while its film's faces over the well keep over this share of the
#: contrast the film's faces beside the well keep since the first frame (:meth:`SilhouetteTracer._flat_or_gone`)
_FACES_KEPT = 0.5
#: the gap (px) beside which rows with none seen are rows where the faces met (:meth:`SilhouetteTracer._gap_rows`)
_GAP_CLOSED = 2.0
#: a dome whose gap to a neighbour's fell under the touching flag's stays that near while its volume keeps over
#: _PARTED_VOLUME of that frame's (growing domes do not part; a dome that lost more collapsed or tore:
#: :meth:`SilhouetteTracer._finish`)
_PARTED_VOLUME = 0.9
#: clipped pixels of the first frame in the base's registration window on under these shares of its columns and of
#: its rows are an annotation burned in (:func:`_unannotated`): narrow, as a scale bar or a stamp's digits are (light
#: clipped by the lamp spans the base), and leaving a quarter of the rows or more to read the columns' drift on
#: (drawn_20261207_128, 2 um/px, a scale bar and its label: 6 % of the columns, 44 % of the window's 82 rows)
_ANNOTATION_COLS, _ANNOTATION_ROWS = 0.25, 0.75
#: how far (px) from the last ok frame's dome the light's plane is not fitted (:meth:`_near_last_dome`)
_DOME_ZONE_PX = 40.0
#: the light's change over the walls' crop is fitted on every _LIGHT_ROWS-th row of it
#: (:meth:`SilhouetteTracer._light_change`)
_LIGHT_ROWS = 4

#: walls read in light the camera clipped (:meth:`SilhouetteTracer._shifted_walls`): the first frame's columns
#: either side of each wall compared (px), the shifts tried (px, coarse then fine steps) and the rows of a band
_SHIFT_HALF = 20
#: ... and the wall's own neighbourhood: _SHIFT_HALF px outside it, _SHIFT_INSIDE inside (its zone); read from that
#: alone when the wider window's misfit (RMS, the bands' median) is over _SHIFT_WORSE times it: the light inside the
#: well changed since the first frame, not only by the light's gain and offset (the liquid diluted, the dome lit
#: it).  Found blind on drawn_20261207_79 and _45 (dilution, the bright side clipped): the wider window's misfit
#: 1.6-2.2x the narrow's, its rims 0.28-0.76 px small; the narrow's within 0.1 px of the unclipped frames'.  On the
#: clipping tests' inverted (1.3x, 1.6x light) the ratio stays 1.04-1.14, and there the narrow window alone read a
#: wall 0.64 px off (its wall lines clipped through their edge): the wider one is kept.  Over the presets and
#: held-out looks under 7 light changes and drawn looks 0-95: 92 ok frames' rims changed, 82 nearer the truth (by
#: up to 0.53 px), 10 further (by up to 0.09 px: drawn_20261207_62's frame 8, 1.39x exposure with 80 % of the view
#: clipped, -0.45 -> -0.51 px)
_SHIFT_INSIDE = 8
_SHIFT_WORSE = 1.25
_SHIFT_RANGE = 4.0
_SHIFT_STEPS = (0.25, 0.01)
_SHIFT_BAND = 10
_SHIFT_SEEN = 0.1  # (the least share of a band's pixels recorded, not clipped, to read it)
#: a frame's walls are read in clipped light (their half level on the rows no clipped pixel can have moved,
#: :func:`osmobulge.imaging._silhouette._moved_by_clip`; with under a third of the rows left, that way) when their
#: crop has more than this many times the first frame's clipped pixels (plus 3): inverted's wall lines, clipped in
#: the first frame, clip 720-770 px of the 789 of the first in frames in the same light, and 1980-2010 with the
#: light 1.05x
_CLIP_GROWTH = 1.1
#: the film beyond each foot checked for a lift (:meth:`SilhouetteTracer._rim_contact`): ``_LIFT_SPAN`` film
#: thicknesses (at least ``_LIFT_MIN_PX``) from ``_LIFT_GAP`` px past the foot, against the change ``_LIFT_FAR``
#: radii out from the rim
_LIFT_SPAN, _LIFT_MIN_PX, _LIFT_GAP, _LIFT_FAR = 1.0, 12.0, 4.0, (0.5, 0.8)
#: how far (px) beyond the outer face the neighbour's dome is looked for (a gap further is not measured: the next
#: frame's search then reaches half of it past the face, never less than the half-way column)
_GAP_REACH = 64.0
#: columns of the base beside each wall that the well's bottom face must stand out against (:meth:`_depth`)
_BESIDE_PX = 40
#: largest difference (px) between the top face's rows at the field's two sides
_MAX_TILT_PX = 1.0
#: a background (the frame's median) below this fraction of its brightest pixels (99.9th percentile) is dark:
#: in bright field, either display polarity, the background is the illumination (0.26-0.96 of the brightest
#: pixels on the looks); in dark field it is the camera's offset and noise (below 0.01 on the dark_field look)
_DARK_BACKGROUND = 0.05


def dark_background(frame):
    """The frame's median over its 99.9th percentile, and why the silhouette route refuses it ("" if it does not).

    Dark-field (annular) light reaches the objective only where the faces bend it
    in, by 20-40 degrees: where those bright zones lie against the faces depends
    on the apertures, and the renderer's thin-object optics is not valid there,
    so this route is neither built nor tested for it.  The black level is taken
    as 0 (a camera offset above ~4 % of full scale passes a dark-field frame,
    which the route then fails to read and says so); against the darkest
    pixels instead, an inverted bright-field display (bright faces on a grey
    background) would look the same as dark field.  Both figures are read on
    every other row and column (a quarter of the pixels, a tenth of the time:
    the ratio lies 0.26-0.96 on the bright-field looks, below 0.01 in dark
    field, far from the 0.05 between them).  Pixels at the frame's greatest
    value are left out when it is more than twice any other pixel's: a level
    no light reached, annotations burned in at the words' full scale over a
    camera of fewer bits (measured: a time stamp at 65535 over 12-bit frames
    refused as dark, 1.8-4.2 %).
    """
    img = np.asarray(np.asarray(frame)[::2, ::2], float)
    top = np.nanmax(img) if img.size else 0.0
    rest = img[img < top]
    if rest.size and top > 2.0 * np.nanmax(rest):
        img = rest
    if np.isnan(img).any():
        hi, mid = float(np.nanpercentile(img, 99.9)), float(np.nanmedian(img))
    else:  # (numpy's, by one selection each)
        hi, mid = percentile(img, 99.9), median(img)
    ratio = mid / hi if hi > 0 else 1.0
    if ratio >= _DARK_BACKGROUND:
        return ratio, ""
    return ratio, (f"the background is dark ({100 * ratio:.1f} % of the brightest pixels, below "
                   f"{100 * _DARK_BACKGROUND:.0f} %): a dark-field (or fluorescence, or background-subtracted) "
                   f"image, which the silhouette route does not read (it reads transmitted bright field, where "
                   f"the faces bend light out of the objective; with annular light the bright zones lie inside "
                   f"the faces by an amount the apertures set); pick the profiles by hand in napari (python -m "
                   f"osmobulge.plugins EXPERIMENT, Profile picker), or for a filled bright band try tracer='band'")


def _relative(img, sigma=25.0, block=4):
    """The local light level (Gaussian of ``sigma`` px), never below a millionth of its maximum.

    It varies over tens of px, so it is computed on means over ``block`` x
    ``block`` px (the block is a box of variance ``(block**2 - 1) / 12`` px**2,
    the coarse Gaussian makes up the rest of ``sigma``) and interpolated back
    linearly: within 0.2 % of the full-resolution Gaussian more than ``sigma``
    px inside the frame (1 % nearer its edges, whose padding differs) on
    the looks, at a fifth of its cost.
    """
    img = np.asarray(img, float)
    h, w = img.shape
    if min(h, w) < 8 * block:
        bg = ndimage.gaussian_filter(img, sigma, mode="nearest")
    else:
        rows, cols = -(-h // block) * block, -(-w // block) * block
        pad = np.pad(img, ((0, rows - h), (0, cols - w)), mode="edge")
        coarse = pad.reshape(rows // block, block, cols // block, block).mean(axis=(1, 3))
        s = np.sqrt(max(sigma**2 - (block**2 - 1) / 12.0, 0.0)) / block
        coarse = ndimage.gaussian_filter(coarse, s, mode="nearest")
        bg = upsample_linear(coarse, (h, w), block)
    return np.maximum(bg, 1e-6 * max(float(bg.max()), 1e-30))


@njit(cache=True, nogil=True)
def _profiles(img):
    """The mean of ``img`` over its columns and over its rows, each less its own mean: what the drift is read
    from (compiled: the frame's own dtype summed in float64, without a float copy of the region)."""
    h, w = img.shape
    r, c = np.empty(h), np.zeros(w)
    for i in range(h):
        acc = 0.0
        for j in range(w):
            v = float(img[i, j])
            acc += v
            c[j] += v
        r[i] = acc / w
    c /= h
    level = r.mean()
    return r - level, c - c.mean(), level


def _unannotated(clipped):
    """The rows and the columns of the registration window (``clipped``: its pixels at the camera's clip level in
    the first frame, or None) free of them, when they are an annotation burned into the frames (a scale bar, a
    time stamp's digits: on under ``_ANNOTATION_COLS`` of the window's columns and ``_ANNOTATION_ROWS`` of its
    rows); None else (no clipped pixel, or light clipped over much of the base: all kept).

    Burned in at the full scale, an annotation does not move with the stage:
    in the base's profiles it pulls the drift read towards none.  Found
    blind on drawn_20261207_128 (2 um/px, a scale bar in the bottom corner
    inside the window): the top face 0.9 px off in every frame (1.7x the
    volume's tolerance at Vtilde 0.18, ok), the full search's lowest rays then
    on the film's fringes beyond the dome (16 % over at Vtilde 4, ok).
    """
    if clipped is None or not clipped.any():
        return None
    rows, cols = clipped.any(axis=1), clipped.any(axis=0)
    if cols.mean() >= _ANNOTATION_COLS or rows.mean() >= _ANNOTATION_ROWS:
        return None
    return ~rows, ~cols


def _deep(rows_p, start):
    """The base's row profile from ``start`` rows into it on, less its mean (what the vertical drift is read
    from: clear of the film)."""
    part = rows_p[start:]
    return part - part.mean()


class _Shift1D:
    """The shift of a 1-D profile against a reference one, by phase correlation (no normalisation) refined on a
    grid of ``1 / upsample`` px: :func:`skimage.registration.phase_cross_correlation` in one dimension (its
    whole-pixel peak, then its upsampled DFT over 1.5 px around it), with the reference's spectrum and the DFT's
    kernel computed once.  ``shift(moving)`` is the shift that registers ``moving`` with the reference."""

    def __init__(self, reference, upsample=20):
        self.ref = np.fft.fft(np.asarray(reference, float))
        self.up = int(upsample)
        n, region = self.ref.size, int(np.ceil(1.5 * self.up))
        self.centre = region // 2
        self.freqs = np.fft.fftfreq(n, self.up)
        self.kernel = np.exp(2j * np.pi * np.arange(region)[:, None] * self.freqs[None, :])

    def shift(self, moving):
        prod = self.ref * np.conj(np.fft.fft(np.asarray(moving, float)))
        n = prod.size
        k = int(np.argmax(np.abs(np.fft.ifft(prod))))
        whole = float(k - n if k > n // 2 else k)
        whole = np.round(whole * self.up) / self.up
        # the cross-correlation at whole + (j - centre) / up, j = 0 .. region - 1
        off = self.centre - whole * self.up
        cc = self.kernel @ (prod * np.exp(-2j * np.pi * off * self.freqs))
        return whole + (int(np.argmax(np.abs(cc))) - self.centre) / self.up


def _vertex(a, b, c):
    """Offset (-0.5..0.5) of the peak of the parabola through three equally spaced values, 0 if not a peak
    (elementwise on arrays)."""
    den = np.asarray(a - 2 * b + c, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.clip(0.5 * (a - c) / den, -0.5, 0.5)
    return np.where(den < 0, off, 0.0)


def _walls_any_depth(maps, k, l0_px, depth_px, **locate):
    """find_walls in the view of quarter turn ``k`` of the flat frame's maps (:class:`FlatMaps`), trying well
    depths of 100, 50, 25 and 200 px when the depth is not known.

    A guess is taken when the well's bottom face is found below the rows the
    walls were searched in (the upper 60 % of the guessed depth).  ``locate``:
    find_walls' ``near`` and ``top_near`` (a given rim).
    """
    if depth_px is not None:
        return find_walls(None, l0_px, depth_px=depth_px, maps=(maps, k), **locate)
    d = np.rot90(maps.size, k)
    err = None
    for guess in (100.0, 50.0, 25.0, 200.0):
        try:
            w = find_walls(None, l0_px, depth_px=guess, maps=(maps, k), **locate)
        except ChamberNotFound as e:
            err = e
            continue
        depth = SilhouetteTracer._depth(d, w)
        if np.isfinite(depth) and depth >= 0.6 * guess:
            return w
        err = ChamberNotFound(f"no well bottom below the walls searched for a {guess:.0f} px deep well")
    raise err


#: the bottom face's strength next to each wall, as a share of its strength over the well's middle, below which the
#: walls are not one well's (:func:`_bottom_span`)
_BOTTOM_SPAN = 0.5


def _bottom_span(d, w, depth):
    """The well's bottom face's strength (the deviation map ``d``'s rows within 2 px of it) over the columns 4-15 %
    of the well's width in from each wall, the weaker side's, as a share of it over the middle 60 %.

    A well's bottom face runs from wall to wall.  Measured on drawn_20261207_23
    cut to a 460 x 860 px field without the chamber given (wells 36 um apart,
    every wall's zone alike on both sides): the chamber's left wall and the
    neighbour's left one were paired, across the base between the wells; the
    bottom face ended 34 px short of that wall, and the flat frame read ok
    with its rim 17 px off.
    """
    r = int(round(w.base_row + depth))
    rows = d[max(r - 2, 0) : r + 3]
    width = w.right - w.left
    mid = np.median(rows[:, int(w.left + 0.2 * width) : int(w.right - 0.2 * width)], axis=1).max()
    ends = [np.median(rows[:, int(a) : max(int(b), int(a) + 1)], axis=1).max() for a, b in
            ((w.left + 0.04 * width, w.left + 0.15 * width), (w.right - 0.15 * width, w.right - 0.04 * width))]
    return float(min(ends) / mid) if mid > 0 else 0.0


def _plausible(d, w, l0_px, depth_px):
    """Why the walls ``w`` found in a view (its deviation map ``d``) are not a chamber seen dome side up ("" if
    they are).

    The well's bottom face must lie below the walls (at ``depth_px`` within
    15 % when known), reaching both (:func:`_bottom_span`), and the flat film's lower face over the well ``l0_px``
    below its top face (within 30 %, when known).
    """
    depth = SilhouetteTracer._depth(d, w)
    if not np.isfinite(depth):
        if depth_px is not None and w.base_row + depth_px > d.shape[0] - 3:
            return (f"no well bottom below the walls: a {depth_px:.0f} px deep well's bottom lies at row "
                    f"{w.base_row + depth_px:.0f}, outside the frame's {d.shape[0]} rows (this route needs the whole "
                    f"well in the field: its bottom and walls register the drift)")
        return "no well bottom below the walls"
    if depth_px is not None and abs(depth - depth_px) > 0.15 * depth_px:
        return f"the well bottom is {depth:.0f} px below the top face's base, not {depth_px:.0f} px"
    span = _bottom_span(d, w, depth)
    if span < _BOTTOM_SPAN:
        return (f"the well's bottom face reaches {span:.2f} of its strength beside the walls at columns "
                f"{w.left:.0f} and {w.right:.0f}: they are not one well's (wells side by side: pass the chamber)")
    if l0_px is not None:
        l0 = _film_thickness(d, w.top_row, w.left, w.right, l0_px)
        if not (np.isfinite(l0) and abs(l0 - l0_px) <= 0.3 * l0_px):
            return f"the flat film over the well is {l0:.1f} px thick, not {l0_px:.1f} px"
    return ""


def _straightest(maps, names, l0_px, depth_px, known_l0, locate=None):
    """Of the orientations ``names`` where the walls are found (``locate(k)``: find_walls' ``near`` and
    ``top_near`` in the view of quarter turn ``k``) and the chamber is plausible (:func:`_plausible`), the one
    with the straightest walls, as ``(name, k, walls)`` (None if none), and why each other one is not.
    ``maps``: the frame's :class:`FlatMaps` (each view's are them turned)."""
    best, errors = None, []
    for name in names:
        k = ROTATIONS[name]
        d = np.rot90(maps.size, k)
        try:
            w = _walls_any_depth(maps, k, l0_px, depth_px, **(locate(k) if locate else {}))
        except ChamberNotFound as err:
            errors.append(f"{name}: {err}")
            continue
        why = _plausible(d, w, l0_px if known_l0 else None, depth_px)
        if why:
            errors.append(f"{name}: {why}")
        elif best is None or w.rms < best[2].rms:
            best = (name, k, w)
    return best, errors


def _upright(maps, l0_px, depth_px, known_l0, radius_px=None):
    """The quarter turn whose view shows a chamber dome side up (walls below a top face), and its walls: the
    straightest plausible one (:func:`_straightest`)."""
    locate = None if radius_px is None else (lambda k: {"radius_px": radius_px})
    best, errors = _straightest(maps, ROTATIONS, l0_px, depth_px, known_l0, locate)
    if best is None:
        raise ChamberNotFound("no top face with two wall silhouettes below it in any orientation (" +
                              "; ".join(errors) + ")")
    return best


def _at_rim(maps, rim, l0_px, depth_px, known_l0, bulge_direction):
    """The orientation, quarter turn and walls of the chamber whose rim is given (stored-frame ``(col, row)`` px
    of the flat mid-line's two ends at the walls), found within a few px of it.

    With ``bulge_direction="auto"``, the two orientations whose top face runs
    along the line through the two points are tried and the plausible one with
    the straighter walls is kept.
    """
    pts = np.asarray(rim, float)
    horizontal = abs(pts[1, 0] - pts[0, 0]) >= abs(pts[1, 1] - pts[0, 1])
    names = [bulge_direction] if bulge_direction != "auto" else (["up", "down"] if horizontal else
                                                                 ["left", "right"])

    def locate(k):  # the rim in the view: the walls' columns and the top face l0/2 above the mid-line
        vx, vy = FrameView(maps.values, k).from_frame(pts[:, 1], pts[:, 0])
        return {"near": tuple(sorted(np.asarray(vx, float))), "top_near": float(np.mean(vy)) - 0.5 * l0_px}

    best, errors = _straightest(maps, names, l0_px, depth_px, known_l0, locate)
    if best is None:
        raise ChamberNotFound("no chamber at the given rim (" + "; ".join(errors) + ")")
    return best


def _film_thickness(d, top_row, left, right, guess):
    """Face-to-face distance (px) of the flat film over the well, or nan.

    Its lower face is the second line below the top face, or (a filled,
    absorbing band) where the band ends, at half its level.
    """
    cols = np.arange(int(left + 0.2 * (right - left)), int(right - 0.2 * (right - left)))
    r0 = int(top_row) + 3
    r1 = min(int(top_row + 2.5 * guess) + 3, d.shape[0] - 1)
    prof = np.median(d[r0:r1, cols], axis=1)
    if prof.size < 5:
        return np.nan
    if prof[0] > 0.5 * prof.max():  # a filled band: its lower edge
        k = int(np.argmax(prof < 0.5 * prof[0]))
        if k == 0:
            return np.nan
        f = (prof[k - 1] - 0.5 * prof[0]) / (prof[k - 1] - prof[k])
        return float(r0 + k - 1 + f - top_row)
    k = int(np.argmax(prof))
    if prof[k] < 0.1 or k in (0, prof.size - 1):
        return np.nan
    return float(r0 + k + _vertex(prof[k - 1], prof[k], prof[k + 1]) - top_row)


def _flat_lift(dev, w, l0, bounds=None, up=12, reach=12):
    """The first frame's film over the well: its mean lift above the top face beside the well (px over the rim
    disc, as a layer: the two sides' mean solid of revolution of the lifts, :func:`revolution_measures`), or nan.

    ``dev``: the view's signed deviation from the light (:class:`FlatMaps`).
    The top face's profile (``up`` rows above it to half the film below), the
    mean of each side's median over the columns beside the well (10 px beyond
    the rims, within ``bounds``, the columns half-way to the neighbouring
    wells), is found in each bin of ``_LIFT_BIN_PX`` columns over the well
    (5 px inside the rims) by its normalised cross-correlation, within
    ``reach`` rows up or down (a parabola's vertex between rows), and the
    bins' lifts pass a running median of 5 (a speck on the face).  A tilt of
    the view lifts one side and lowers the other: the mean of the two sides'
    solids leaves it out.  nan (no word) when the rows run out of the frame
    or fewer than 10 columns lie beside the well (neighbours nearer than
    about 2.2 radii).
    """
    top, rim, axis = w.top_row, w.rim_radius, w.axis_col
    r0, r1 = int(np.floor(top)) - up, int(np.ceil(top + 0.5 * l0))
    if r0 - reach < 0 or r1 + reach > dev.shape[0]:
        return np.nan
    u = np.arange(dev.shape[1]) - axis
    lo, hi = (-np.inf, np.inf) if bounds is None else (bounds[0] - axis, bounds[1] - axis)
    sides = [(u < -rim - 10.0) & (u > lo), (u > rim + 10.0) & (u < hi)]
    sides = [c for c in sides if c.sum() >= 5]
    n_bins = int(2.0 * (rim - 5.0) // _LIFT_BIN_PX)
    if sum(c.sum() for c in sides) < 10 or n_bins < 6:
        return np.nan
    band = dev[r0 - reach : r1 + reach]
    face = band[reach : reach + r1 - r0]
    tmpl = np.mean([np.median(face[:, c], axis=1) for c in sides], axis=0)  # (each side's: a tilt cancels)
    tmpl = tmpl - tmpl.mean()
    c0 = int(round(axis - 0.5 * n_bins * _LIFT_BIN_PX))
    if c0 < 0 or c0 + n_bins * _LIFT_BIN_PX > dev.shape[1]:
        return np.nan
    bins = np.median(band[:, c0 : c0 + n_bins * _LIFT_BIN_PX].reshape(band.shape[0], n_bins, _LIFT_BIN_PX), axis=2)
    seg = np.lib.stride_tricks.sliding_window_view(bins.T, r1 - r0, axis=1)  # (bin, start row, row)
    seg = seg - seg.mean(axis=2, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        cc = (seg @ tmpl) / np.sqrt(np.einsum("ijk,ijk->ij", seg, seg) * (tmpl @ tmpl))
    cc = np.nan_to_num(cc, nan=-1.0)
    j = np.argmax(cc, axis=1)
    inner = np.clip(j, 1, cc.shape[1] - 2)
    i = np.arange(n_bins)
    off = np.where((j > 0) & (j < cc.shape[1] - 1), _vertex(cc[i, inner - 1], cc[i, inner], cc[i, inner + 1]), 0.0)
    lift = ndimage.median_filter(reach - (j + off), 5, mode="nearest")  # (a window starting reach - L rows up)
    x = c0 + (i + 0.5) * _LIFT_BIN_PX - axis
    m = revolution_measures(np.r_[-rim, x, rim], np.r_[0.0, lift, 0.0])  # (signed: a sag is a negative solid)
    return float(m.volume / (np.pi * rim**2))


def _first_edges(v, t, sign, noise, size=9):
    """The outer edge along each profile of ``v`` (rows sampled at ``t`` px, from outside in; the dome's change
    has sign ``sign``) as a position in ``t`` (nan where none), whether found, whether it jumped (more than
    ``_JUMP_PX`` off the running median of ``size`` profiles'), the threshold, and the figures ``dome_contrast``
    (median strongest change / noise) and ``edge_sign`` (profiles whose strongest change has the dome's sign)."""
    extreme = v[np.arange(v.shape[0]), np.argmax(np.abs(v), axis=1)]
    strength = np.abs(extreme)
    prof = np.clip(sign * v, 0.0, None)
    thr = max(8.0 * noise, 0.2 * median(prof.max(axis=1)))
    edge = outer_edges(prof, float(thr), int(12.0 / abs(float(t[1] - t[0]))))
    te = np.interp(edge, np.arange(t.size), t, left=np.nan, right=np.nan)
    found = np.isfinite(te)
    med = running_percentile(np.where(found, te, median(te[found]) if found.any() else 0.0), 50.0, size)  # (median)
    jump = found & (np.abs(te - med) > _JUMP_PX)
    strong = strength > 10.0 * noise
    figs = {"dome_contrast": median(strength) / max(noise, 1e-12),
            "edge_sign": float(np.mean(np.sign(extreme[strong]) == sign)) if strong.any() else 0.0}
    return te, found, jump, thr, figs


def _in_front(on, phis, t, centre, width, gap):
    """The samples of the rays' change that belong to something in front of this chamber's dome (in the water
    outside it: a neighbour's dome, a time stamp burned into the frames, debris), or None when there is none.

    ``on``: the change above the edge threshold, one row a ray at angle ``phis`` from the rim plane, sampled at
    ``t`` px from its centre ``centre`` (col, row in the view, ``width`` columns wide), from outside in.  The
    dome's face is the connected piece of ``on`` that is the outermost on the most rays (at least half of
    them).  Another piece is in front of it when ``_FRONT_SHARE`` of its samples lie more than ``gap`` px
    outside the dome's piece on their ray (the film's faces and fringes lie within a film thickness or so of
    its outer face), or, if it reaches the field's side edges (a neighbour's dome whose well is beyond them),
    outside it at all: those rays' first edge is sought behind it.  A piece of the dome's own face cut off from
    the rest has nothing of the dome behind it and stays.  With the dome's piece at the field's top (a dome out
    of the field: field_margin's business), None.

    Measured (2026-12-06): wells 3 radii apart in a 1000 px field, their walls beyond it, so no bounds were
    known: their domes came in at the sides and every dome frame of this chamber was traced out to them
    (poor_fit field_margin, 5.6-32x the tolerance); a time stamp burned into the frames' top corner (its digits
    change each frame) took the full search's rays towards it: every dome frame flagged on the 12 looks read by
    this route (field_margin, gap_length).
    """
    lab, n = ndimage.label(on, structure=np.ones((3, 3), bool))
    if n < 2:
        return None
    seen = on.any(axis=1)
    outermost = lab[np.flatnonzero(seen), np.argmax(on[seen], axis=1)]
    count = np.bincount(outermost, minlength=n + 1)
    main = int(np.argmax(count))
    if count[main] < 0.5 * on.shape[0]:
        return None
    dome = lab == main
    cols = centre[0] + t[None, :] * np.cos(phis)[:, None]
    rows = centre[1] - t[None, :] * np.sin(phis)[:, None]
    if np.any(dome & (rows < 2.0)):
        return None
    has, first = dome.any(axis=1), np.argmax(dome, axis=1)  # (the dome's outermost sample on each ray)
    lead = np.where(has[:, None], first[:, None] - np.arange(on.shape[1])[None, :], -1)  # (samples ahead of it)
    pieces = np.arange(1, n + 1)
    far = ndimage.mean(lead > gap / abs(float(t[1] - t[0])), lab, index=pieces) >= _FRONT_SHARE
    ahead = ndimage.mean(lead > 0, lab, index=pieces) >= _FRONT_SHARE
    side = ndimage.maximum(on & ((cols < 2.0) | (cols > width - 3.0)), lab, index=pieces) > 0
    front = pieces[(far | (side & ahead)) & (pieces != main)]
    return np.isin(lab, front) if front.size else None


def _least_distance(points, others):
    """The least distance between ``others`` (N, 2) and ``points`` (M, 2)."""
    from scipy.spatial import cKDTree

    return float(np.min(cKDTree(points).query(others)[0]))


def _mad(v):
    """The scaled MAD of all the samples of ``v`` (the standard deviation of normal noise)."""
    return 1.4826 * median(np.abs(v - median(v)))


def _light_plane(v, cols, rows, bins=_TILT_BINS, iters=3, exclude=None):
    """A plane ``(c0, c1, c2)``, ``c0 + c1 col + c2 row``, fitted to the change ``v`` of horizontal transects
    (one a row, at view ``rows``; its samples at view columns ``cols``, the same shape as ``v``) through the
    medians of ``bins`` runs of columns each, those more than 3 scaled MADs off the plane dropped ``iters`` times
    (a dome's lines and the band over its pole are outliers to it; its inside, liquid for water, has the water's
    light), without the runs with a sample in ``exclude`` (a bool array like ``v``: a dyed film's band is not),
    or None (fewer than 6 finite medians)."""
    n = (v.shape[1] // bins) * bins
    med = np.median(v[:, :n].reshape(v.shape[0], bins, -1), axis=2).ravel()
    if exclude is not None:
        med[exclude[:, :n].reshape(v.shape[0], bins, -1).any(axis=2).ravel()] = np.nan
    x = np.mean(cols[:, :n].reshape(v.shape[0], bins, -1), axis=2).ravel()
    y = np.repeat(np.asarray(rows, float), bins)
    a = np.column_stack((np.ones_like(x), x, y))
    keep = np.isfinite(med)
    for _ in range(iters):
        if keep.sum() < 6:
            return None
        c = np.linalg.lstsq(a[keep], med[keep], rcond=None)[0]
        r = med - a @ c
        keep = np.isfinite(med) & (np.abs(r) <= 3.0 * max(_mad(r[keep]), 1e-12))
    return c


def _speck_map(sd, clipped):
    """Per pixel of ``sd`` (the flat frame's signed deviation above the top face), the distance (px) to the
    nearest speck (a value more than 6 scaled MADs off its row's median), inf without any.

    The scaled MAD is that of the pixels not ``clipped`` (at the frame's
    greatest value, full scale): in water exposed past full scale most pixels
    sit at the ceiling, the MAD of all of them is about 0 and every pixel the
    noise takes below the ceiling was a speck (measured on ho_blind_1206q:
    27 % of the pixels, the neighbour's dome not seen 12 px off, the gap
    read as 32 px and the frame before the domes met traced 2.7x the
    tolerance off).
    """
    dev = np.abs(sd - np.median(sd, axis=1, keepdims=True))
    free = dev[~clipped]
    scale = 1.4826 * float(np.median(free)) if free.size else 0.0
    speck = (dev > 6.0 * max(scale, 1e-12)) & ~clipped
    if not speck.any():
        return np.full(sd.shape, np.inf)
    return ndimage.distance_transform_edt(~speck)


def _ends(a, x, b):
    """``x`` between ``a`` and ``b`` (``np.r_[a, x, b]`` without its parsing: the per-frame paths build many)."""
    return np.concatenate(([a], x, [b]))


def _station_arcs(length, step, foot_step=None, foot_arc=_FOOT_ARC_PX):
    """Arc lengths (px) of the stations along a curve of ``length`` px, not its two ends (the feet): every
    ``step`` px, and every ``foot_step`` px within ``foot_arc`` px of either end (where the dome turns into the
    top face: measured while the final curve still ran through the rim, sparser stations there let it cut the
    corner, by 0.5-3 px at 3 px spacing, -0.1 % of the volume; they are the face's ends now)."""
    if foot_step is None or length <= 2.0 * foot_arc:
        step = step if foot_step is None else foot_step
        return np.linspace(0.0, length, max(int(np.ceil(length / step)) + 1, 3))[1:-1]
    ends = np.arange(foot_step, foot_arc, foot_step)
    mid = np.linspace(foot_arc, length - foot_arc, max(int(np.ceil((length - 2.0 * foot_arc) / step)) + 1, 2))
    return np.concatenate((ends, mid, length - ends[::-1]))


def _scatter(u, z):
    """The scatter (px) of points along a curve across it: the scaled MAD of their second differences over
    sqrt(6) (white noise of sigma along the normals gives second differences of sigma sqrt(6); a smooth curve's own
    bend, curvature times the spacing squared, is 0.03 px at 3 px on a radius of 300 px); 0 for fewer than 5."""
    if len(u) < 5:
        return 0.0
    return 1.4826 * median(np.hypot(np.diff(u, 2), np.diff(z, 2))) / np.sqrt(6.0)


def _least_bend(xy, chord, share=0.1):
    """How little the outer face bends anywhere: the least turn of its direction over ``share`` of its arc, over
    its mean turn over as much (1: a circle's, the same everywhere; 0: a straight stretch; below 0: bent the other
    way).  Its points ``xy`` lie every px from one foot over the top to the other; its direction at each is that
    of the chord between the points ``chord`` px before and after (a glitch of a few px, noise, barely turn it).
    nan when it turns less than ``_BEND_MIN_DEG`` in all (a low dome: too little bend to tell a straight stretch).

    A membrane under pressure bends everywhere (its meridian is convex); a cap torn off the pole leaves a flat top.
    """
    c = max(int(round(chord)), 1)
    n = len(xy)
    if n < 2 * c + 3:
        return np.nan
    i = np.arange(c, n - c)
    d = xy[i + c] - xy[i - c]
    theta = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    total = theta[-1] - theta[0]
    w = int(share * (theta.size - 1))
    if abs(total) < np.radians(_BEND_MIN_DEG) or w < 2:
        return np.nan
    return float(np.min((theta[w:] - theta[:-w]) / (total * w / (theta.size - 1))))


def _station_shares(xy):
    """Each station's share of the curve (px): half the distances to its two neighbours (the whole one at the
    ends)."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    if seg.size == 0:
        return np.ones(len(xy))
    return np.concatenate(([seg[0]], 0.5 * (seg[1:] + seg[:-1]), [seg[-1]]))


@njit(cache=True, nogil=True)
def _thickness(u, z, r0_l, r0_r, l0):
    r"""The film's thickness along a mid-surface curve (left rim -> right rim), px.

    Kinematics of an incompressible film of uniform meridional stretch: each
    half's material radius runs linearly in arc length :math:`s` from
    :math:`R_0` at the rim to 0 at the pole, :math:`R_0` (``r0_l``, ``r0_r``)
    the rim radius in the flat first frame, whose film is :math:`l_0` thick
    (the rim's later widening, the pre-stretch, stretches that film and adds
    none; :math:`\lambda_{pre} = R/R_0`, supplement Sec. 5.7).  So
    :math:`\lambda_1 = L/R_0` (half the curve's arc length over
    it), :math:`\lambda_2 = r/(R_0 (1 - s/L))` and :math:`l = l_0/(\lambda_1
    \lambda_2)`: :math:`l_0/\lambda_1^2` at the pole, :math:`l_0/(\lambda_1
    \lambda_{pre})` at the rim.  Whatever the law, :math:`\int l\,dA = l_0
    \pi R_0^2` (the film over the well is conserved), so the volume between the
    outer face and the mid-surface is right to first order in :math:`l`.

    (Compiled: called three times a frame on a curve of ~700 points; the pole
    is the point nearest the axis, :math:`\lambda_1` at least 1, :math:`\lambda_2`
    at least 1e-3 and equal to :math:`\lambda_1` within 1 px of the pole, the
    thickness at most :math:`l_0`; nan stays nan.)
    """
    n = u.size
    arc = np.empty(n)
    arc[0] = 0.0
    for i in range(1, n):
        arc[i] = arc[i - 1] + np.hypot(u[i] - u[i - 1], z[i] - z[i - 1])
    pole = int(np.argmin(np.abs(u)))
    out = np.empty(n)
    for i in range(n):
        if i <= pole:  # (the left half: arc length from its rim; the right one's from its own)
            rim, dist, length = r0_l, arc[i], arc[pole]
        else:
            rim, dist, length = r0_r, arc[n - 1] - arc[i], arc[n - 1] - arc[pole]
        length = length if not length < 1e-9 else 1e-9
        lam1 = length / rim
        lam1 = lam1 if not lam1 < 1.0 else 1.0
        r0 = rim * (1.0 - min(max(dist, 0.0), length) / length)  # material radius
        lam2 = abs(u[i]) / (r0 if not r0 < 1e-9 else 1e-9) if r0 > 1.0 else lam1
        lam2 = lam2 if not lam2 < 1e-3 else 1e-3
        t = l0 / (lam1 * lam2)
        out[i] = t if not t > l0 else l0
    return out


def _foot(p, t, most=40.0):
    """Where the outer face's end ``p`` (``(u, z)`` px from the axis and the top face) carried on along ``t``
    (unit, away from the face) meets the top face (z = 0), at most ``most`` px on: shape (1, 2), or (0, 2) when it
    does not come down or is down already (measured in docs/architecture.md: the small chamber's volume 0.09 %
    low without it)."""
    if t[1] >= -1e-3 or p[1] <= 0.0:
        return np.zeros((0, 2))
    return (p + min(p[1] / -t[1], most) * t)[None, :]


class _Polyline:
    """A curve through ordered points ``xy`` (N, 2), by arc length: its points by linear interpolation, its tangent
    that of the segment there.  The track's curve (:meth:`SilhouetteTracer._finish`): the outer face's spline
    sampled every px (linear between 1 px samples of a curve of radius 300 px: 4e-4 px off it), with its ends
    carried down to the top face (:func:`_foot`) and on to the feet at the rim; what
    :meth:`SilhouetteTracer._normals` takes of a :class:`ProfileSpline` (``length``, the points and the tangents),
    without a second spline fitted each frame."""

    def __init__(self, xy):
        xy = np.asarray(xy, float)
        seg = np.diff(xy, axis=0)
        ln = np.hypot(seg[:, 0], seg[:, 1])
        keep = ln > 1e-9  # (a repeated point: no segment)
        self.xy = np.concatenate((xy[:1], xy[1:][keep]))
        self.arc = np.concatenate(([0.0], np.cumsum(ln[keep])))
        self.length = float(self.arc[-1])
        self.dirs = seg[keep] / ln[keep, None]

    def __call__(self, s):
        s = np.clip(np.asarray(s, float), 0.0, self.length)
        return np.column_stack((np.interp(s, self.arc, self.xy[:, 0]), np.interp(s, self.arc, self.xy[:, 1])))

    def tangent(self, s):
        i = np.searchsorted(self.arc, np.asarray(s, float), side="right") - 1
        return self.dirs[np.clip(i, 0, len(self.dirs) - 1)]


def _shift_misfits(f, seen, y, flat, bad, cols, shifts):
    """:meth:`SilhouetteTracer._shifted_walls`' misfit of one band at each of ``shifts``: the mean square
    residual (over the pixels fitted, less the 4 unknowns) of ``f = a + b y + (c + d y) flat(cols - shift)``
    fitted by least squares over the pixels ``seen`` (not clipped here) whose two ``flat`` neighbours are not
    ``bad`` (clipped in the first frame); inf where under ``_SHIFT_SEEN`` of the band's pixels are left.

    ``f``, ``seen``, ``y``: the band (rows x len(cols)); ``flat``, ``bad``: the
    first frame's rows of the band, every column; ``flat`` linearly
    interpolated.  All the shifts at once (the normal equations of each).
    """
    x = cols[None, :] - np.asarray(shifts)[:, None]  # (shift, column)
    i = np.floor(x).astype(int)
    t = (x - i)[:, None, :]
    ts = flat[:, i].transpose(1, 0, 2) * (1.0 - t) + flat[:, i + 1].transpose(1, 0, 2) * t  # (shift, row, column)
    w = (seen[None] & ~(bad[:, i] | bad[:, i + 1]).transpose(1, 0, 2)).astype(float)
    n = w.sum(axis=(1, 2))
    basis = (np.ones_like(ts), np.broadcast_to(y, ts.shape), ts, y * ts)
    ata = np.empty((len(shifts), 4, 4))
    atf = np.empty((len(shifts), 4))
    for a in range(4):
        wa = w * basis[a]
        atf[:, a] = np.einsum("srk,rk->s", wa, f)
        for b in range(a, 4):
            ata[:, a, b] = ata[:, b, a] = np.einsum("srk,srk->s", wa, basis[b])
    ftf = np.einsum("srk,rk->s", w, f * f)
    out = np.full(len(shifts), np.inf)
    ok = n >= max(_SHIFT_SEEN * f.size, 5)
    if np.any(ok):
        scale = np.sqrt(np.einsum("sii->si", ata[ok])) + 1e-30  # (the normal equations scaled: well conditioned;
        # a ridge of 1e-10 so that a band whose first-frame light is one grey, its columns collinear, is no error)
        a_s = ata[ok] / scale[:, :, None] / scale[:, None, :] + 1e-10 * np.eye(4)
        c = np.linalg.solve(a_s, (atf[ok] / scale)[..., None])[..., 0]
        rss = ftf[ok] - np.einsum("si,si->s", c, atf[ok] / scale)
        out[ok] = np.maximum(rss, 0.0) / (n[ok] - 4)
    return out


def _shifted_wall(crop, flat, clip, bad, j0, jn, off, rows):
    """One wall of :meth:`SilhouetteTracer._shifted_walls` read over the window ``off`` (columns about the first
    frame's wall ``j0``; ``jn``: this frame's expected): ``(ys, ws, misfit, near)``, the bands' middle rows, their
    wall columns, the median of their least misfits (:func:`_shift_misfits`) and the bands' pixels within 3 px of
    the wall clipped here or, shifted, in the first frame; None when the window leaves the crop.

    ``crop``, ``flat``, ``clip``, ``bad``: this frame's walls' crop, the
    first frame's (the drift to the pixel taken off) and their clipped
    pixels; ``rows``: the first and last rows of the walls' strip.
    """
    reach = int(np.ceil(_SHIFT_RANGE)) + 1
    coarse = np.arange(-_SHIFT_RANGE, _SHIFT_RANGE + 1e-9, _SHIFT_STEPS[0])
    t_win = int(round(j0)) + off
    if t_win[0] - reach < 0 or t_win[-1] + reach >= crop.shape[1]:
        return None
    moved = int(round(jn)) - int(round(j0))  # (whole px from the first frame's wall to the expected: from the top
    # band on, each band's search starts from the last band's wall, so a wall leaning more than it did in the first
    # frame is followed down)
    ys, ws, misfits, near = [], [], [], []
    r0, r1 = rows
    for b0 in range(r0, r1 - _SHIFT_BAND // 2, _SHIFT_BAND):
        b1 = min(b0 + _SHIFT_BAND, r1)
        f_win = t_win + moved
        if f_win[0] < 0 or f_win[-1] >= crop.shape[1]:
            break
        near.append((clip[b0:b1, f_win] | bad[b0:b1, t_win])[:, np.abs(off) <= 3])
        f = crop[b0:b1, f_win]
        seen = ~clip[b0:b1, f_win]
        if np.count_nonzero(seen) < _SHIFT_SEEN * seen.size:
            continue
        y = np.broadcast_to((np.arange(b0, b1) - 0.5 * (b0 + b1 - 1))[:, None], f.shape)
        e = _shift_misfits(f, seen, y, flat[b0:b1], bad[b0:b1], t_win, coarse)
        k = int(np.argmin(e))
        fine = np.arange(coarse[k] - _SHIFT_STEPS[0], coarse[k] + _SHIFT_STEPS[0] + 1e-9, _SHIFT_STEPS[1])
        fine = fine[np.abs(fine) <= _SHIFT_RANGE]
        e = _shift_misfits(f, seen, y, flat[b0:b1], bad[b0:b1], t_win, fine)
        k = int(np.argmin(e))
        if not np.isfinite(e[k]):
            continue
        d = fine[k] + (_vertex(e[k - 1], e[k], e[k + 1]) * _SHIFT_STEPS[1] if 0 < k < e.size - 1 else 0.0)
        ys.append(0.5 * (b0 + b1 - 1))
        ws.append(j0 + moved + d)
        misfits.append(e[k])
        moved += int(round(d))
    return ys, ws, (float(np.sqrt(np.median(misfits))) if misfits else np.inf), near


def _strip_rows(base, depth, n):
    """The first and last (exclusive) rows of the walls' strip (``_STRIP`` of the well's ``depth`` px below the
    base's top surface, row ``base``) within a crop of ``n`` rows."""
    return max(int(base + _STRIP[0] * depth), 0), min(int(base + _STRIP[1] * depth), n)


def _near_walls(clip, w, depth):
    """The larger share, over the two walls ``w``, of the walls' strip's pixels within 3 px of the wall's column
    that ``clip`` marks clipped (the figure ``clipped_share``)."""
    r0, r1 = _strip_rows(w.base_row, depth, clip.shape[0])
    shares = [np.mean(clip[r0:r1, max(int(round(c)) - 3, 0) : int(round(c)) + 4]) if r1 > r0 else 0.0
              for c in (w.left, w.right)]
    return float(max(shares))


class SilhouetteTracer:
    """Follows one chamber seen by its silhouettes through a series (see the module's notes).

    The same interface as :class:`osmobulge.imaging.trace.ChamberTracer`
    (``ref``, ``k``, ``process``), so :func:`osmobulge.imaging.extract.extract`
    runs either.

    Parameters
    ----------
    first_frame : ndarray of shape (H, W)
        The flat membrane.
    l0_px : float, optional
        Membrane thickness (px); measured from the flat film's two faces when not given.
    depth_px : float, optional
        Well depth (px), where the walls are searched (its upper half); measured when not given.
    bulge_direction : {"auto", "up", "down", "left", "right"}
    settings : TraceSettings, optional
        ``max_drift``, ``residual_flag``, ``asymmetry_flag`` and ``gap_flag`` are used.
    rim : array_like of shape (2, 2), optional
        The flat membrane's mid-line ends at the two walls, stored-frame
        ``(col, row)`` px (e.g. the ends of a flat profile picked in napari):
        the top face and walls are then looked for within a few px of them
        (``max(l0/2, 4)`` rows, 20 columns) instead of over the frame.
    radius_px : float, optional
        The chamber's radius (px) when known: a pair of wall zones more than
        15 % off it is not taken when a pair of it is there (several wells
        side by side, :func:`_silhouette._wall_pair`).
    """

    route = "silhouette"

    def __init__(self, first_frame, *, l0_px=None, depth_px=None, bulge_direction="auto", settings=None, rim=None,
                 radius_px=None):
        frame = np.asarray(first_frame)
        if frame.ndim != 2:
            raise ValueError(f"frames must be 2-D (H, W), got shape {frame.shape}")
        self.settings = settings or TraceSettings()
        _, dark = dark_background(frame)
        if dark:
            raise ChamberNotFound(dark)
        guess = 25.0 if l0_px is None else float(l0_px)
        near = None
        # the local light and the deviation from it, once: every view's below are them turned
        values = np.asarray(frame, float)
        maps = FlatMaps(values, _relative(values))
        if rim is not None:
            rim = np.asarray(rim, float)
            if rim.shape != (2, 2) or not np.all(np.isfinite(rim)):
                raise ValueError(f"rim must be two finite (col, row) points, shape (2, 2); got shape {rim.shape}")
            if np.hypot(*(rim[1] - rim[0])) < 40:  # (find_walls' narrowest well)
                raise ValueError(f"the rim's two points are {np.hypot(*(rim[1] - rim[0])):.0f} px apart: they are "
                                 f"the flat mid-line's ends at the two walls, at least 40 px apart")
            bulge_direction, self.k, w = _at_rim(maps, rim, guess, depth_px, l0_px is not None, bulge_direction)
            near = (w.left, w.right)
        elif bulge_direction == "auto":
            bulge_direction, self.k, w = _upright(maps, guess, depth_px, l0_px is not None, radius_px)
        else:
            self.k = ROTATIONS[bulge_direction]
            w = _walls_any_depth(maps, self.k, guess, depth_px, radius_px=radius_px)
            why = _plausible(np.rot90(maps.size, self.k), w, l0_px, depth_px)
            if why:
                raise ChamberNotFound(f"no chamber seen dome side {bulge_direction}: {why}")
        self.bulge_direction = bulge_direction
        img, light, _ = maps.view(self.k)
        d = np.rot90(maps.size, self.k)
        if l0_px is None:  # the flat film's faces over the well
            l0_px = _film_thickness(d, w.top_row, w.left, w.right, guess)
            if not (np.isfinite(l0_px) and l0_px > 1.0):
                raise ChamberNotFound("the flat film's lower face over the well is not seen: pass the chamber "
                                      "(its membrane thickness)")
        else:  # the flat film's two faces must be the membrane's thickness apart: else the top face is off
            seen = _film_thickness(d, w.top_row, w.left, w.right, float(l0_px))
            self.film_mismatch = float(abs(seen - l0_px)) if np.isfinite(seen) else np.inf
        self.l0 = float(l0_px)
        if depth_px is None:
            depth_px = self._depth(d, w, w.top_row + self.l0)
            if not np.isfinite(depth_px):
                raise ChamberNotFound("the well's bottom face is not seen below the walls: pass the chamber "
                                      "(its depth)")
        self.depth = float(depth_px)
        w = find_walls(None, self.l0, depth_px=self.depth, top_row=w.top_row, strip=_STRIP, near=near,
                       maps=(maps, self.k), radius_px=None if near is not None else radius_px)
        self._check_upright(d, w)
        self._check_flat(d, w)
        self.walls0 = w
        # the columns (view, first frame) half-way to the nearest neighbouring wells' walls: this chamber's dome is
        # searched for between them, and a frame whose dome comes near them, or with a dome's face on them, is
        # touching (:meth:`_neighbour_gap`); None without neighbours
        nb = neighbour_walls(maps, self.k, w, self.depth, strip=_STRIP)
        self.bounds = None if not np.isfinite(nb).any() else (
            0.5 * (nb[0] + w.left) if np.isfinite(nb[0]) else -np.inf,
            0.5 * (nb[1] + w.right) if np.isfinite(nb[1]) else np.inf)
        self._nb = nb  # (the neighbours' nearest walls' columns, view, first frame)
        # the film over the well must lie on the top face: every frame's change is measured from this frame
        dev = np.rot90(maps.deviation, self.k)
        self.flat_lift = _flat_lift(dev, w, self.l0, self.bounds)
        self._lim = None  # (per row, the columns the dome is searched for between, once a gap was measured)
        self._lim_next = None  # (this frame's measured ones, for the next frame)
        self._side_seen = None  # (the first frame a dome came in at the field's side in, :meth:`_side_gap`)
        self._touched = None  # (the last frame whose dome came within the touching flag of a neighbour's: its
        # index, gap and volume, :meth:`_finish`)
        # (the flat frame's specks above the top face: not a neighbour's dome, :meth:`_neighbour_gap`,
        # :meth:`_side_gap`; mapped when first asked for, :meth:`_clear_of_specks`)
        top = max(int(w.top_row), 1)
        self._speck_map = None
        self._speck_src = (dev[:top],
                           np.rot90(maps.values, self.k)[:top] == maps.values.max())
        self._rim0 = (w.axis_col - w.left, w.right - w.axis_col)  # the film's material rim radii (:func:`_thickness`)
        self.polarity = 0  # the dome's sign (+1 darker than the water), from the first frame showing it
        self.shape = frame.shape
        self.ref = self._geometry(w)
        self.blur = np.nan
        self._flat = native_frame(frame)  # (stored orientation: sampled in the view by quarter turn k)
        # (its pixels the camera clipped, in the view; None when none is: :meth:`_walls`)
        clip0 = clip_mask(self._flat)
        self._clip0 = None if clip0 is None else np.rot90(clip0, self.k)
        self._bg = np.ascontiguousarray(light, np.float32)  # (in the view)
        self.view_shape = img.shape
        # the base below the film (walls, well bottom), registered frame to frame; no dome there.  The vertical
        # drift is read from its rows from half the well's depth below the film on (``_reg_deep`` into them): a
        # frame moved down by less than that keeps the film out of them (read from all of them, 5 px below the
        # film on, a frame the stage moved 6-8 px down brought the film's band into their top rows, which then
        # outweighed the well's bottom face: the drift read 40 px off, the walls lost; 2 of the held-out looks,
        # moved by up to 20 px each way, read frames 3x and 26x their volume tolerance off, ok)
        self._reg_rows = (int(np.ceil(w.base_row + 5)), min(int(w.base_row + self.depth) + 40, img.shape[0]))
        self._reg_deep = min(int(np.ceil(max(0.5 * self.depth - 5.0, 0.0))),
                             (self._reg_rows[1] - self._reg_rows[0]) // 2)
        self._reg_keep = _unannotated(None if self._clip0 is None else self._clip0[slice(*self._reg_rows)])
        rows_p, cols_p, self._reg_level = self._reg_profiles(img)
        self._reg_ref = (_Shift1D(_deep(rows_p, self._reg_deep)), _Shift1D(cols_p))
        self.prev = None
        self._edge_reached = (None, np.inf)  # the last frame with a dome and its margin to the field's edge, px
        self._track = None  # the last ok frames' outer faces (u, z), px (one or two)
        self._curves = None  # and their curves with the feet at the rim (:class:`_Polyline`, :meth:`_finish`)
        self._splines = []  # the splines of the track's curves (:meth:`_spline`)
        self.searches = 0  # frames whose outer face was searched for by rays (not tracked)
        self.one_pass = 0  # frames tracked in one pass (:meth:`_one_pass`)
        self.film_mismatch = getattr(self, "film_mismatch", 0.0)  # px (0: l0 measured from these faces)

    # ---------------------------------------------------------------------- first frame
    @staticmethod
    def _depth(d, w, base_row=None):
        """Well depth (px) below ``base_row`` (default the walls'): the strongest row over the well's middle
        that is weak outside it (the bottom face), outside being the base's ``_BESIDE_PX`` columns beside each
        wall, 20 px out (not the whole field's: neighbouring wells' bottoms lie on the same row; measured on a
        look with a neighbour each side 133 px off, over most of the field's other columns, whose well was
        refused as having no bottom), or the 10 columns 4 px beside each wall when they are weaker (measured on
        drawn_20261207_23 in a 460 px wide field: the wells 33 px apart, the columns 20 px out lay in the
        neighbours' wells, whose bottoms the chamber's matched, and the view was refused)."""
        base_row = w.base_row if base_row is None else base_row
        c0, c1 = int(w.left + 0.2 * (w.right - w.left)), int(w.right - 0.2 * (w.right - w.left))
        r0 = int(base_row + 20)
        if r0 >= d.shape[0] - 3:
            return np.nan
        inside = np.median(d[r0:, c0:c1], axis=1)
        out_cols = np.r_[np.arange(max(int(w.left) - 20 - _BESIDE_PX, 0), max(int(w.left) - 20, 0)),
                         np.arange(min(int(w.right) + 20, d.shape[1]), min(int(w.right) + 20 + _BESIDE_PX, d.shape[1]))]
        outside = np.median(d[r0:, out_cols], axis=1) if out_cols.size else np.zeros_like(inside)
        near = np.r_[np.arange(max(int(w.left) - 14, 0), max(int(w.left) - 4, 0)),
                     np.arange(min(int(w.right) + 5, d.shape[1]), min(int(w.right) + 15, d.shape[1]))]
        if near.size:  # (the base right beside the walls: those columns may lie in a neighbouring well)
            outside = np.minimum(outside, np.median(d[r0:, near], axis=1))
        score = inside - outside
        k = int(np.argmax(score))
        return float(r0 + k - base_row) if score[k] > 0.1 else np.nan

    def _check_upright(self, d, w):
        """Refuse a tilted view: the top face left and right of the well must lie on one row within a pixel.

        The lag between the two sides' mean profiles across the top face
        (their cross-correlation's peak, sub-pixel): any look of the face.
        """
        lo, hi = max(int(w.top_row) - 15, 0), min(int(w.top_row) + 16 + int(self.l0), d.shape[0])
        sides = [d[lo:hi, sl].mean(axis=1) for sl in (slice(0, int(w.left) - 10), slice(int(w.right) + 10, None))
                 if d[lo:hi, sl].shape[1] >= 20]
        if len(sides) < 2:
            return
        a, b = (x - x.mean() for x in sides)
        lags = np.arange(-8, 9)
        cc = np.array([np.sum(a[8:-8] * np.roll(b, -k)[8:-8]) for k in lags])
        k = int(np.argmax(cc))
        lag = float(lags[k])
        if 0 < k < lags.size - 1:
            lag += _vertex(cc[k - 1], cc[k], cc[k + 1])
        if abs(lag) > _MAX_TILT_PX:
            raise ChamberNotFound(f"the top face is tilted ({lag:+.1f} px from the left of the field to its "
                                  f"right): the silhouette tracer needs an upright view; rotate the series or pick "
                                  f"the profiles")

    @staticmethod
    def _check_flat(d, w):
        """Refuse a first frame with a dome already standing: it is the reference every change is measured from.

        Over the well, the water above the top face must look as it does beside
        the well: a feature in most of its columns (the largest difference from
        the rows' median beside the well, smoothed over 1 px; median over the
        columns) above a quarter of the walls' level is a dome.
        """
        rim = w.rim_radius
        r1 = int(w.top_row) - 4
        r0 = max(int(w.top_row - 3.0 * rim), 0)
        c0, c1 = max(int(w.axis_col - rim), 0), min(int(w.axis_col + rim) + 1, d.shape[1])
        beside = np.r_[np.arange(0, max(int(w.axis_col - 1.6 * rim), 0)),
                       np.arange(min(int(w.axis_col + 1.6 * rim), d.shape[1]), d.shape[1])]
        if r1 - r0 < 3 or c1 - c0 < 10 or beside.size < 10:
            return
        walls = d[int(w.base_row + 5) : int(w.base_row + 40)]
        wall_level = float(np.percentile(walls, 99.9)) if walls.size else 1.0
        rows = ndimage.gaussian_filter(d[r0:r1], 1.0)
        diff = np.abs(rows[:, c0:c1] - np.median(rows[:, beside], axis=1)[:, None])
        level = float(np.median(diff.max(axis=0))) / max(wall_level, 1e-12)
        if level > 0.25:
            raise ChamberNotFound(f"a dome already stands above the top face in this frame (feature level "
                                  f"{level:.2f} of the walls' over the well): the first frame must show the flat "
                                  f"membrane")

    def _geometry(self, w):
        rim = w.rim_radius
        line = Line(float(w.axis_col), float(w.top_row + 0.5 * self.l0), 0.0)
        return ChamberGeometry(line=line, thickness=self.l0, polarity=1 if self.polarity >= 0 else -1,
                               rim_radius=float(rim), well=Well(-float(rim), float(rim), depth=self.depth),
                               wall_rms=float(w.rms))

    # ---------------------------------------------------------------------- one frame
    def _reg_profiles(self, img):
        """The registration window's (:attr:`_reg_rows` of the view ``img``) :func:`_profiles`: the row profile
        and the level over the columns :func:`_unannotated` keeps, the column profile over the rows it keeps."""
        win = img[slice(*self._reg_rows)]
        if self._reg_keep is None:
            return _profiles(win)
        rows_keep, cols_keep = self._reg_keep
        rows_p, _, level = _profiles(win[:, cols_keep])
        return rows_p, _profiles(win[rows_keep])[1], level

    def _walls(self, img, rows_p, cols_p, raw=None):
        """This frame's walls, its drift (dx, dy) from the first frame (``rows_p``, ``cols_p``: its base's
        :func:`_profiles`), the share of the walls' pixels the camera clipped (0 unless it clipped light the
        first frame's was not; ``raw``: the view as recorded, ``img`` before its light's gain was divided out) and
        the figure ``wall_misfit`` when the walls were matched to the first frame's profile (else 1).

        In clipped light the walls are read by their half level on the rows
        whose read no clipped pixel can have moved (clipping lowers only the
        brightest pixels and keeps their order: those rows read as unclipped;
        found blind on drawn_20261207_111, 2 um/px, 2-17 % of the walls'
        pixels clipped, whose walls matched to the first frame's profile read
        0.2 px in, lambda_pre 0.4-0.5 % off, ok); when under a third of a
        wall's rows are left, by :meth:`_shifted_walls`."""
        # the drift: the base's row and column profiles (its mean over columns and over rows; the well's bottom
        # face and the walls) registered against the first frame's, each by phase correlation
        dy, dx = -self._reg_ref[0].shift(_deep(rows_p, self._reg_deep)), -self._reg_ref[1].shift(cols_p)
        if max(abs(dx), abs(dy)) > self.settings.max_drift:
            raise ChamberNotFound(f"the base moved {np.hypot(dx, dy):.0f} px since the first frame, more than "
                                  f"max_drift ({self.settings.max_drift:g} px): if the stage was moved, raise it "
                                  f"(settings=TraceSettings(max_drift=...), --max-drift-px)")
        w0 = self.walls0
        # only the strip of the base the walls are followed down, and the columns around them
        top = w0.top_row + dy
        lo = max(int(top + self.l0 + _STRIP[0] * self.depth) - 2, 0)
        hi = min(int(top + self.l0 + _STRIP[1] * self.depth) + 3, img.shape[0])
        # each wall's columns: _WALL_MARGIN outside it (its edge and the light beyond), _WALL_INSIDE inside (where
        # find_walls looks for its zone's peak, within 20 px of the expected column); the two side by side
        left, right = w0.left + dx, w0.right + dx
        spans = [(max(int(left) - _WALL_MARGIN, 0), int(left) + _WALL_INSIDE),
                 (int(right) - _WALL_INSIDE, min(int(right) + _WALL_MARGIN, img.shape[1]))]
        if spans[0][1] >= spans[1][0]:  # (a narrow well: its columns in one piece)
            spans = [(spans[0][0], spans[1][1])]
        cols = np.concatenate([np.arange(a, b) for a, b in spans])
        width0 = spans[0][1] - spans[0][0]
        # the local light: the flat frame's, moved by the drift to the pixel (it varies over tens of px; the
        # walls' half level lies between the zone's extreme and the light just outside, whatever its scale)
        rows = np.clip(np.arange(lo, hi) - int(round(dy)), 0, img.shape[0] - 1)
        moved = np.clip(cols - int(round(dx)), 0, img.shape[1] - 1)
        crop = np.concatenate([img[lo:hi, a:b] for a, b in spans], axis=1)
        c0, c1 = spans[0][0], spans[-1][0] - (width0 if len(spans) == 2 else 0)  # (crop column -> view column)
        # more of the walls' light clipped than in the first frame (the same share, its clipped wall lines moved
        # with the walls, reads as the first frame did: measured on inverted, within 0.05 px)
        clip = None if raw is None else clip_mask(np.concatenate([raw[lo:hi, a:b] for a, b in spans], axis=1))
        clip0 = None if clip is None or self._clip0 is None else self._clip0[np.ix_(rows, moved)]
        n0 = 0 if clip0 is None else np.count_nonzero(clip0)
        flat = np.rot90(self._flat, self.k)[np.ix_(rows, moved)].astype(float)  # (the first frame's crop)
        clipped = clip is not None and np.count_nonzero(clip) > _CLIP_GROWTH * n0 + 3
        light = self._bg[np.ix_(rows, moved)]
        add, gain = self._light_change(crop, flat, rows, moved, light)
        light = light + add + gain * light
        try:
            # the first frame in this light: where this frame differs from it beyond the walls' shift (a particle
            # drifting past a wall), find_walls leaves the wall's rows out; and the rows whose half level or
            # crossing a clipped pixel may have moved (the other rows' read is exact)
            w = find_walls(crop, self.l0, depth_px=self.depth, top_row=top - lo, strip=_STRIP,
                           near=(left - c0, right - c1), light=light, reference=flat * (1.0 + gain) + add,
                           clipped=clip if clipped else None)
            share, misfit = (_near_walls(clip, w, self.depth) if clipped else 0.0), 1.0
        except ChamberNotFound:
            if not clipped:
                raise
            # too few rows left: the walls read by matching the first frame's profile over what was recorded
            at = (w0.left + int(round(dx)) - c0, w0.right + int(round(dx)) - c1)  # (the first frame's, crop columns)
            near = at
            if self.prev is not None and self.prev.geometry is not None:  # (the last ok frame's, this drift)
                g, mx = self.prev.geometry, dx - self.prev.drift[0]
                near = (g.line.x0 - g.rim_radius + mx - c0, g.line.x0 + g.rim_radius + mx - c1)
            w, share, misfit = self._shifted_walls(np.asarray(crop, float), flat, clip, clip0, top - lo, at, near)
        return replace(w, top_row=w.top_row + lo, base_row=w.base_row + lo, left=w.left + c0,
                       right=w.right + c1), dx, dy, share, misfit

    def _shifted_walls(self, crop, flat, clip, clip0, top, at, near):
        """The walls of a frame with more light clipped than the first frame (:data:`_CLIP_GROWTH`) over most
        of their rows (:meth:`_walls`), read by matching the first frame's profile across each wall over the
        pixels this frame recorded; the larger share, over the two walls, of the pixels within 3 px of a wall
        left out as clipped; and the larger, over the two walls, of the misfit of the window read over the least
        of the two windows' (``wall_misfit``: over ``_SHIFT_WORSE``, the frame is flagged).

        ``crop``: this frame's walls' crop; ``flat``: the first frame's, the
        drift to the pixel taken off; ``clip``, ``clip0``: their pixels the
        camera clipped (``clip0`` None when the first frame has none);
        ``top``: the top face's row; ``at``: the first frame's walls' crop
        columns; ``near``: this frame's expected (the last ok frame's).

        A clipped pixel's light is a bound: the walls' half level read from
        it is too low and their edges move (measured: the inverted look, its
        light 1.6x, read 0.6 px off, ok; the same frames unclipped, within
        0.01 px; here within 0.13 px, or not found).  Per band of
        ``_SHIFT_BAND`` rows of the walls' strip, and each column of a window
        about the wall (:func:`_shifted_wall`): this frame ``= a + b y + (c
        + d y) flat(x - shift)`` (the light's change, linear down the band;
        ``flat`` linearly interpolated) by least squares over the pixels
        clipped neither here nor, shifted, in the first frame
        (:func:`_shift_misfits`), for shifts within ``_SHIFT_RANGE`` px (steps
        of 0.25, then 0.01 px about the best), the first band's from the
        expected wall, each next band's from the last band's (the walls lean
        more as the pre-stretch grows: on edge_dark at Vtilde 4 a wall's top
        is 8.6 px out of the first frame's, its foot 2.3 px).  The bands'
        walls are fitted by a line down the strip and read at the base's top
        surface; their RMS about it is the walls' ``rms`` (over
        ``MAX_WALL_RMS``: not found, as :func:`find_walls`).  Each wall is
        read in two windows: ``_SHIFT_HALF`` px outside it and
        ``_SHIFT_INSIDE`` inside (its edge and zone), and ``_SHIFT_HALF``
        either side; the wider is taken unless its misfit is over
        ``_SHIFT_WORSE`` times the narrower's (the light inside the well
        changed otherwise than by the gain and offset fitted) or its line is
        not straight.  A window taken though its misfit is over
        ``_SHIFT_WORSE`` times the other's (the narrower's line not
        straight) is a read neither window gives: the frame is flagged
        (``wall_misfit``; found blind on drawn_20261207_100, its exposure up
        29 %: the wall's own window's bands 1-2 px apart, the wider's misfit
        8.7x, the rim 0.85 px in, ok).
        """
        base = top + self.l0
        rows = _strip_rows(base, self.depth, crop.shape[0])
        bad = np.zeros(flat.shape, bool) if clip0 is None else clip0
        cols, rms, shares, worse = [], [], [], []
        for side, (j0, jn) in enumerate(zip(at, near, strict=True)):
            reads = []  # (misfit, column, scatter, near_clip): the wall's own neighbourhood, then the wider window
            for inside in (_SHIFT_INSIDE, _SHIFT_HALF):  # (outside is left of the left wall)
                off = np.arange(-_SHIFT_HALF, inside + 1) if side == 0 else np.arange(-inside, _SHIFT_HALF + 1)
                read = _shifted_wall(crop, flat, clip, bad, j0, jn, off, rows)
                if read is None:
                    raise ChamberNotFound("a wall lies too near the crop's edge to be read in clipped light")
                ys, ws, misfit, near_clip = read
                if len(ws) >= 3:
                    fit = np.polyfit(ys, ws, 1)
                    scatter = float(np.std(np.asarray(ws) - np.polyval(fit, ys)))
                    reads.append((misfit, float(np.polyval(fit, base)), scatter, near_clip))
            if not reads:
                raise ChamberNotFound("a wall's profile is clipped over most of its rows: its edge is not seen "
                                      "in the light the camera recorded (lower the exposure)")
            held = [r for r in reads if r[2] <= MAX_WALL_RMS]
            if len(held) == 2:  # (the wider window unless its misfit shows the light inside the well changed)
                held = held[:1] if held[1][0] > _SHIFT_WORSE * held[0][0] else held[1:]
            taken, col, scatter, near_clip = (held or reads)[-1]
            shares.append(float(np.mean(np.concatenate(near_clip))) if near_clip else 1.0)
            cols.append(col)
            rms.append(scatter)
            worse.append(taken / min(r[0] for r in reads) if taken > 0.0 else 1.0)
        if max(rms) > MAX_WALL_RMS:  # (as find_walls: not straight walls)
            raise ChamberNotFound(f"the walls read in light the camera clipped are not straight lines (row "
                                  f"scatter {max(rms):.2f} px > {MAX_WALL_RMS} px): too little of their profile "
                                  f"was recorded (lower the exposure)")
        return (SilhouetteWalls(float(top), float(base), cols[0], cols[1], max(rms)), max(shares),
                float(max(worse)))

    def _light_change(self, crop, flat, rows, moved, light):
        """How much brighter this frame's light is than the first frame's over the walls' ``crop`` (``flat``: the
        first frame's, view ``rows`` and ``moved`` columns: the crop's less the drift to the pixel; ``light``: the
        first frame's light there): the planes ``(s, L - 1)`` over the crop, the light ``s + (L - 1) light``
        brighter, fitted to this frame less the first, ``s + (L - 1) flat`` (least squares over every
        ``_LIGHT_ROWS``-th row, again without the pixels more than 3 scaled MADs off the first fit: the residue of
        the drift's fraction of a px at the walls' edges, and the walls' own widening).

        Stray light (a window, the room's lamps) adds ``s`` to the light the
        walls' half level is read against, a lamp brighter on one side scales
        it by ``L`` (and the gain step, a frame divided by its light's ratio,
        turns the one into the other).  Measured with stray light growing to
        20 % of full scale on one side of the halo look: against the first
        frame's light the walls' zones were taken 6-10 px off and frames lost
        (``wall_rms``).
        """
        sub = slice(None, None, _LIGHT_ROWS)
        flat = flat[sub]
        diff = (crop[sub] - flat).ravel()
        level = max(float(np.mean(light)), 1e-9)
        x = (moved - moved.mean()) / max(np.ptp(moved), 1)  # (scaled: the normal equations well conditioned)
        y = (rows - rows.mean()) / max(np.ptp(rows), 1)
        a = np.empty((diff.size, 6))
        a[:, 0], a[:, 1], a[:, 2] = 1.0, np.tile(x, flat.shape[0]), np.repeat(y[sub], x.size)
        a[:, 3:] = a[:, :3] * (flat.ravel() / level)[:, None]
        keep = np.isfinite(diff)
        for last in (False, True):
            ak = a[keep]  # (the normal equations of 6 unknowns)
            try:
                c = np.linalg.solve(ak.T @ ak, ak.T @ diff[keep])
            except np.linalg.LinAlgError:  # (a crop of one grey: s and L - 1 not told apart, their sum is)
                c = np.linalg.lstsq(ak.T @ ak, ak.T @ diff[keep], rcond=None)[0]
            if not last:
                r = diff - a @ c
                keep &= np.abs(r) <= 3.0 * max(_mad(r[keep]), 1e-9)
        x, y = x[None, :], y[:, None]
        return c[0] + c[1] * x + c[2] * y, (c[3] + c[4] * x + c[5] * y) / level

    def process(self, frame, index=0, *, guide=None, manual=None):
        """Measure one frame (``guide`` is not needed by this route and ignored); returns a FrameTrace."""
        out = self._measure(frame, index, manual)
        if out.message:
            return out
        if out.flag_figure == "flat_lift":
            out.message = (f"the first frame is not flat: its film over the well stands {self.flat_lift:+.2f} px above "
                           f"the top face beside the well (a layer over the rim disc; a low dome's silhouette reads "
                           f"under its own), and every frame's change is measured from it as the flat membrane: "
                           f"give a frame of the flat membrane (reference_frame=), pick the profiles by hand, or keep "
                           f"the frames you judge right (curation: keep flagged)")
        elif out.flag_figure == "flat_film":
            out.message = (f"the flat film's two faces in the first frame are {self.film_mismatch:.1f} px off the "
                           f"membrane's thickness ({self.l0:.1f} px): the top face every height is measured from is in "
                           f"doubt (is the chamber's thickness right? is the first frame flat?)")
        return out

    def _measure(self, frame, index, manual):
        frame = np.asarray(frame)
        if frame.shape != self.shape:
            raise ValueError(f"frame {index} has shape {frame.shape}, expected {self.shape}")
        frame = native_frame(frame)  # (no copy when it is already the kernels' kind)
        img = raw = np.rot90(frame, self.k)  # (a view: only the crops the walls are read on are copied)
        out = FrameTrace(index=index)
        rows_p, cols_p, level = self._reg_profiles(img)
        gain = level / self._reg_level if self._reg_level > 0 else 1.0
        if gain > 0.0 and abs(gain - 1.0) > _GAIN_TOL:  # (the light changed since the first frame: read in its
            # light; a black frame is left as it is)
            frame = np.ascontiguousarray(frame / gain, np.float32)
            img = np.rot90(frame, self.k)
        out.figures["light_gain"] = float(gain)
        try:
            w, dx, dy, out.figures["clipped_share"], out.figures["wall_misfit"] = self._walls(img, rows_p, cols_p, raw)
        except ChamberNotFound as err:
            out.message = f"chamber walls not found: {err}"
            out.flag, out.flag_figure, out.flag_value = "no_membrane", "wall_rms", np.nan
            return out
        g = self._geometry(w)
        out.geometry, out.drift = g, (dx, dy)
        if manual is not None:
            return self._from_points(frame, g, out, manual)

        tilt = None  # (the light's change across the view since the first frame, once measured: :meth:`_noise`)

        def sample(points, directions, offsets, own=True):
            v = self._change(frame, points, directions, offsets, dx, dy)
            if tilt is None and not (own and self.bounds is not None):
                return v
            cols = points[:, :1] + offsets[None, :] * directions[:, :1]  # (the samples' view columns)
            if tilt is not None:  # (divided out: (frame - L flat) / (L light), L - 1 the plane, flat ~ light)
                p = tilt[0] + tilt[1] * cols + tilt[2] * (points[:, 1:] + offsets[None, :] * directions[:, 1:])
                v = (v - p) / (1.0 + p)
            if own and self.bounds is not None:  # (this chamber's columns only: no neighbour's dome)
                if self._lim is None:
                    v[(cols < self.bounds[0] + dx) | (cols > self.bounds[1] + dx)] = 0.0
                else:  # (each row's own limits, :meth:`_neighbour_gap`)
                    lo, hi = self._limits(points[:, 1:] + offsets[None, :] * directions[:, 1:], dy)
                    v[(cols < lo + dx) | (cols > hi + dx)] = 0.0
            return v

        # (the base's rows clipped: their gain is a bound, the water's light may have changed by more)
        clipped_base = clip_level(raw[slice(*self._reg_rows)]) is not None
        noise, tilt, out.figures["light_tilt"] = self._noise(sample, w, clipped_base)
        u = z = None
        if self._track is not None:  # along the normals of the last frame's outer face
            u, z, figs = self._tracked(sample, w, noise)
        if u is None and dx == 0.0 and dy == 0.0 and np.array_equal(frame, self._flat):
            figs = {"dome_contrast": 0.0}  # (the reference frame itself: its change is 0 on every ray)
        elif u is None:  # the full search: rays from the rim plane's centre
            self.searches += 1
            u, z, figs = self._outer_face(sample, w, noise)
        out.figures.update(figs)
        if u is None:  # no dome: flat (the film unchanged) or gone
            self._track = self._curves = None
            out = self._flat_or_gone(sample, w, noise, g, out)
            last, margin = self._edge_reached
            if margin < FIELD_MARGIN_PX:  # (a dome does not shrink: it grew on out of the field)
                out.message = f"no dome edge found: {field_edge_message(margin, last)}"
                out.figures["field_margin"] = margin
                out.flag, out.flag_figure, out.flag_value = "poor_fit", "field_margin", margin
            elif out.flag == "ok" and self.prev is not None and self.prev.height > _LOW_DOME_PX:
                # a dome does not fall flat between frames: its edge was not seen (measured on ho_blind_1206d:
                # domes over most of the noise's rows, a dyed liquid inside them, raised the noise until the
                # dome's contrast fell below 10 of it; such frames read flat and ok, 33x the tolerance)
                out.message = (f"no dome edge found (its contrast {out.figures['dome_contrast']:.1f}x the noise) "
                               f"where frame {self.prev.index} had a dome {self.prev.height:.0f} px high")
                out.flag, out.flag_figure, out.flag_value = "poor_fit", "dome_contrast", out.figures["dome_contrast"]
            return out
        self._edge_reached = (index, figs.get("field_margin", np.inf))
        out.figures["rim_contact"] = self._rim_contact(sample, w, u, z, noise)
        # (the sides with no neighbouring well seen: a neighbour's dome may come in at the field's edge there)
        open_sides = [j for j in (0, 1) if self.bounds is None or not np.isfinite(self.bounds[j])]
        side = self._side_gap(sample, w, u, z, dx, dy, noise, open_sides) if open_sides else np.inf
        if np.isfinite(side) and self._side_seen is None:
            self._side_seen = index
        if self.bounds is None:
            if np.isfinite(side):
                out.figures["neighbour_gap"] = side
            return self._finish(u, z, w, g, out)
        self._lim_next = None
        out.figures["neighbour_gap"] = min(self._neighbour_gap(sample, w, u, z, dx, dy, noise), side)
        out = self._finish(u, z, w, g, out)
        if self._lim_next is not None and out.flag in ("ok", "touching"):  # (the next frame's search limits)
            self._lim = self._lim_next
        return out

    def _rim_contact(self, sample, w, u, z, noise):
        """Whether the film just outside the rims still lies on the top surface: 1 - the share of the
        ``_LIFT_SPAN`` film thicknesses beyond each foot (the outer face's outermost point within 2 l0 of the top
        face, plus ``_LIFT_GAP`` px of its halo) over which the change on the film's rows (l0 above to l0 below
        the top face) is loud from the foot on, least of the two sides (1: on the surface, 0: lifted all along;
        nan: no side with its reference in this chamber's columns).

        Loud: over 10x the noise and 3x the same rows' median change ``_LIFT_FAR`` radii out (a film shifted
        everywhere is a misregistration, not a lift).  Measured on painted delaminated frames (the film lifted
        1.5 l0 at the rim, over 0.3 a), read by this route as ok 4.8-7.2x the tolerance off: this route had no
        delamination check.
        """
        a = w.rim_radius
        rows = w.top_row + self.l0 * np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
        low = z < 2.0 * self.l0
        contact = np.nan
        dx = w.axis_col - self.walls0.axis_col  # (the drift: the bounds are the first frame's columns)
        for j, side in enumerate((-1.0, 1.0)):
            # the reference: within the frame and this chamber's columns (measured on three wells 40 um apart:
            # beyond them it is 0, and a top face shifted by a fraction of a px read as a lift on every frame);
            # none, no word on this side
            edge = self.view_shape[1] - 1.0 if side > 0 else 0.0
            if self.bounds is not None and np.isfinite(self.bounds[j]):
                edge = side * min(side * edge, side * (self.bounds[j] + dx))
            far0 = w.axis_col + side * (1.0 + _LIFT_FAR[0]) * a
            far_len = min((_LIFT_FAR[1] - _LIFT_FAR[0]) * a, side * (edge - far0))
            if far_len < 0.1 * a:
                continue
            mine = low & (side * u > 0.0)
            start = max(float(np.max(side * u[mine])) if mine.any() else a, a) + _LIFT_GAP
            pts = np.column_stack((np.full(rows.size, w.axis_col + side * start), rows))
            dirs = np.tile([side, 0.0], (rows.size, 1))
            near = np.max(np.abs(sample(pts, dirs, np.arange(0.0, max(_LIFT_SPAN * self.l0, _LIFT_MIN_PX), 1.0))),
                          axis=0)
            pts[:, 0] = far0
            far = np.max(np.abs(sample(pts, dirs, np.arange(0.0, far_len, 1.0))), axis=0)
            loud = near > max(10.0 * noise, 3.0 * float(np.median(far)))
            run = int(np.argmin(loud)) if not loud.all() else loud.size  # (from the foot on)
            contact = np.nanmin([contact, 1.0 - run / loud.size])
        return float(contact)

    def _limits(self, rows, dy):
        """The columns (first frame's view) the dome is searched for between at view rows ``rows`` of a frame
        drifted by ``dy`` rows (:attr:`_lim`)."""
        idx = np.clip(np.rint(rows - dy), 0, self._lim[0].size - 1).astype(np.intp)
        return self._lim[0][idx], self._lim[1][idx]

    def _neighbour_gap(self, sample, w, u, z, dx, dy, noise):
        """How near (px) the dome comes to a neighbouring well's dome; how near it comes to the columns it was
        searched for between (beyond them it is not seen) when that is less than the touching flag's figure.

        Those columns are first the ones half-way to the neighbouring wells
        (:attr:`bounds`).  Once the dome comes within ``_NEAR_PX`` of one, or
        a dome's face (a change of either sign over 10x the noise, not a
        speck of the flat frame) lies on one above the top face, the gap is
        measured row by row (:meth:`_gap_rows`) in this and every later
        frame, and the next frame's dome is searched for, on each row, up to
        the middle of the gap there (measured on ho_blind_1206c and 1206k: a
        dome reaching the half-way column flagged touching 4 frames before
        the neighbour's dome was near it).
        """
        gap = np.inf
        rows = np.arange(w.top_row - 2.0 * _FOOT_PX, 0.0, -1.0)
        lim = None
        for j, (side, b) in enumerate(((-1.0, self.bounds[0]), (1.0, self.bounds[1]))):
            if not np.isfinite(b):
                continue
            limit = b if self._lim is None else self._limits(w.top_row - z, dy)[j]
            dist = side * (limit + dx - w.axis_col - u)
            near = float(np.min(dist))
            if self._lim is None and near > _NEAR_PX and not self._face_on(sample, side, b, rows, dx, dy, noise):
                gap = min(gap, near)
                continue
            g, mid = self._gap_rows(sample, w, u, z, side, dx, dy, noise)
            # (the gap measured; the face at its limits may be cut off there: that distance then, unless the water
            # just beyond it is quiet, :meth:`_cut_at_limit`)
            close = dist < self.settings.touching_flag
            if close.any() and self._cut_at_limit(sample, w, u, z, close, noise):
                gap = min(gap, g, near)
            else:
                gap = min(gap, g)
            if lim is None:
                lim = [np.full(self.view_shape[0], x) for x in self.bounds]
            lim[j] = mid
        if lim is not None:
            self._lim_next = tuple(lim)
        return max(gap, 0.0)

    def _cut_at_limit(self, sample, w, u, z, close, noise):
        """Whether the dome's outer face may be cut off at its points ``close`` (of its points ``(u, z)``, left
        rim -> right rim: those at the columns it was searched for between, :meth:`_limits`): a change over 10x
        the noise beyond any of them along the curve's outward normal, unmasked, from 5 px (the face's own edge
        fades within 3-4 px) to a film's thickness and 8 px (an edge-only look's inner face taken for the outer
        one has the outer face that far out): the face going on past the limit, or anything else there, and the
        frame stays touching.  Quiet water there: the face ends where it was found.

        Measured on drawn_20261207_27 (frame 6): a drifting particle 52 px
        past the face in frame 5 was taken for the neighbour's dome, the next
        frame's search limited to the middle of that gap; the dome grew 26 px
        sideways between the frames, reached the limit and was flagged
        touching, the water beyond it quiet and the neighbour's dome 50 px off.
        (Along the normal, not the row: near the dome's top a row runs along
        the face.)
        """
        du, dz = np.gradient(u), np.gradient(z)
        norm = np.hypot(du, dz)
        norm[norm == 0.0] = 1.0
        nu, nz = -dz / norm, du / norm  # (outward: the curve runs left rim -> over the top -> right rim)
        v = sample(np.column_stack((w.axis_col + u[close], w.top_row - z[close])),
                   np.column_stack((nu[close], -nz[close])), np.arange(5.0, max(12.0, self.l0 + 8.0) + 0.5),
                   own=False)
        return bool(np.any(np.abs(v) > 10.0 * noise))

    def _side_gap(self, sample, w, u, z, dx, dy, noise, sides=(0, 1)):
        """How near (px) the dome comes to a dome coming in at the field's side edges ``sides`` (0 left, 1 right:
        those with no neighbouring well seen, :attr:`bounds`), a neighbour's whose well lies beyond the field;
        inf when there is none.

        A change of either sign over 10x the noise, not on a speck of the flat frame, on such an edge's column
        above the top face, more than ``_NEAR_PX`` from the dome's outer face (points ``(u, z)``), is a dome
        coming in there.  The change over 10x the noise on a grid of ``_SIDE_STEP`` px over the water above the
        top face falls into connected pieces; the gap is 0 when the piece at that edge is the one at the dome's
        outer face (the two changes merge: the domes touch, or their halos do), else the least distance from
        that piece to the outer face.  Measured (2026-12-06) on wells 3.1 radii apart (halo look, their walls
        beyond the field): the domes overlapping by 2 px read ok, not touching, 0.68 of the tolerance off; now
        touching, and the gaps before it 1.9-3.2 px short of the bands' (the neighbour's halo).
        """
        top = np.floor(w.top_row - 2.0 * _FOOT_PX)
        if top < 2.0 * _SIDE_STEP:
            return np.inf
        rows = np.arange(0.0, top + 1.0, _SIDE_STEP)
        n_cols = self.view_shape[1]
        face = np.column_stack((w.axis_col + u, w.top_row - z))
        edges = np.array([1.0 if j == 0 else n_cols - 2.0 for j in sides])
        v = sample(np.column_stack((edges, np.zeros(edges.size))), np.tile([0.0, 1.0], (edges.size, 1)), rows,
                   own=False)
        loud = np.abs(v) > 10.0 * noise
        if not loud.any():
            return np.inf
        loud &= self._clear_of_specks(rows[None, :], edges[:, None], dx, dy)
        sides = [j for j, col, on in zip(sides, edges, loud, strict=True) if on.any()
                 and _least_distance(face, np.column_stack((np.full(int(on.sum()), col), rows[on]))) > _NEAR_PX]
        if not sides:
            return np.inf
        cols = np.arange(0.0, n_cols - 1.0, _SIDE_STEP)
        v = sample(np.column_stack((np.zeros(rows.size), rows)), np.tile([1.0, 0.0], (rows.size, 1)), cols,
                   own=False)
        on = (np.abs(v) > 10.0 * noise) & self._clear_of_specks(rows[:, None], cols[None, :], dx, dy)
        lab, _ = ndimage.label(on, structure=np.ones((3, 3), bool))
        # the dome's pieces: those within a grid step of its outer face's points
        ri = np.clip(np.rint(face[:, 1] / _SIDE_STEP).astype(np.intp), 0, rows.size - 1)
        ci = np.clip(np.rint(face[:, 0] / _SIDE_STEP).astype(np.intp), 0, cols.size - 1)
        at_face = np.zeros(on.shape, bool)
        at_face[ri, ci] = True
        dome = np.unique(lab[ndimage.binary_dilation(at_face, np.ones((3, 3), bool))])
        gap = np.inf
        for j in sides:
            pieces = np.unique(lab[:, -1 if j else 0])
            pieces = pieces[pieces > 0]
            if np.intersect1d(pieces, dome[dome > 0]).size:
                return 0.0
            rr, cc = np.nonzero(np.isin(lab, pieces))
            if rr.size:
                gap = min(gap, _least_distance(face, np.column_stack((cols[cc], rows[rr]))))
        return gap

    def _face_on(self, sample, side, b, rows, dx, dy, noise):
        """Whether a dome's face (a change of either sign over 10x the noise) lies on the half-way column ``b``
        at ``rows`` above the top face, not where a speck of the flat frame, fixed to the camera, lies within
        the drift of the column."""
        if not (rows.size and 0.0 <= b + dx < self.view_shape[1] - 1):
            return False
        v = sample(np.array([[b + dx, rows[0]]]), np.array([[0.0, -1.0]]), rows[0] - rows, own=False)[0]
        clear = self._clear_of_specks(rows, np.full(rows.shape, b + dx), dx, dy)
        return bool(np.any(clear & (np.abs(v) > 10.0 * noise)))

    def _clear_of_specks(self, rows, cols, dx, dy):
        """Whether view points (this frame) lie farther from the flat frame's specks (dust fixed to the camera:
        the change shows them where they are and moved by the drift) than the drift and ``_SPECK_PX``."""
        if self._speck_map is None:
            self._speck_map, self._speck_src = _speck_map(*self._speck_src), None
        m = self._speck_map
        rr = np.clip(np.rint(rows - dy), 0, m.shape[0] - 1).astype(np.intp)
        cc = np.clip(np.rint(cols - dx), 0, m.shape[1] - 1).astype(np.intp)
        return m[rr, cc] > np.hypot(dx, dy) + _SPECK_PX

    def _gap_rows(self, sample, w, u, z, side, dx, dy, noise):
        """The gap (px) between the dome's outer face (points ``(u, z)``) and the neighbouring dome on side
        ``side`` (-1 left, +1 right), and the columns (first frame's view, one per row) half-way across it.

        On every row above the top face up to ``_GAP_ROWS`` above the dome,
        from the outer face outwards (above the dome, from its outermost
        column) to the neighbour's wall, at most ``_GAP_REACH`` px: past the
        face's own change (over 10x the noise), the first change over 10x the
        noise not on a speck of the flat frame is the neighbour's dome; the
        gap is its offset, a running median over ``_GAP_ROWS`` rows, least over
        the rows (when none is seen, the least length scanned); 0 where the two
        changes merge.  On
        rows where nothing is seen half-way is taken to the scan's end, never
        nearer than :attr:`bounds`; the other rows keep :attr:`bounds`.
        """
        j = int(side > 0)
        n_rows = self.view_shape[0]
        # the outer face's outermost column on each row (the points joined every half px)
        seg = np.hypot(np.diff(u), np.diff(z))
        arc = np.r_[0.0, np.cumsum(seg)]
        t = np.arange(0.0, arc[-1] + 0.5, 0.5)
        cu, cz = np.interp(t, arc, u), np.interp(t, arc, z)
        ri = np.rint(w.top_row - cz).astype(np.intp)
        r0 = max(int(ri.min()) - _GAP_ROWS, 0)
        rows = np.arange(float(r0), np.floor(w.top_row - 2.0 * _FOOT_PX) + 1.0)
        ri -= r0
        keep = (ri >= 0) & (ri < rows.size)
        reach = np.full(rows.size, -np.inf)
        np.maximum.at(reach, ri[keep], side * cu[keep])
        start = w.axis_col + side * np.where(np.isfinite(reach), reach, np.max(side * u))
        wall = self._nb[j] + dx if np.isfinite(self._nb[j]) else (0.0 if side < 0 else self.view_shape[1] - 1.0)
        length = np.clip(side * (wall - start), 0.0, _GAP_REACH)
        offs = np.arange(0.0, max(float(length.max()), 1.0), 1.0)
        v = sample(np.column_stack((start, rows)), np.tile([side, 0.0], (rows.size, 1)), offs, own=False)
        loud = np.abs(v) > 10.0 * noise
        clear = self._clear_of_specks(rows[:, None], start[:, None] + side * offs[None, :], dx, dy)
        inside = offs[None, :] < length[:, None]
        # (a sample on a speck is neither loud nor quiet: it does not end the face's own change; taken for quiet,
        # the face's change just past it read as the neighbour's, a gap of 1 px on one row: ho_blind_1206k's frame
        # 7, 10.5 px apart, touching through the rows closed beside it)
        calm = (~loud & clear) | ~inside
        loud &= clear & inside
        quiet = np.argmax(calm, axis=1)  # (past the face's own change)
        merged = ~np.any(calm & inside, axis=1) & np.any(loud, axis=1)  # (no water before the neighbour's wall)
        after = loud & (offs[None, :] >= quiet[:, None])
        hit = np.where(after.any(axis=1), offs[np.argmax(after, axis=1)], np.inf)
        hit[merged] = 0.0
        # (the face at the half-way column and a gap closing to _GAP_CLOSED px beside rows with none: the
        # neighbour's face met the outer face there and its change was taken for the face's own; drawn_20261207_44,
        # its domes overlapping, read 7 px, ok)
        if np.any(side * (self.bounds[j] + dx - start) <= 1.0):
            runs, _ = ndimage.label(np.isinf(hit))  # (each run of rows with no gap seen)
            beside = ndimage.minimum_filter1d(hit, 3) <= _GAP_CLOSED  # (next to a gap that closed)
            met = np.unique(runs[beside & (runs > 0)])
            hit[np.isin(runs, met)] = 0.0
        # (mirrored at the ends: padded with the end row's own value, a change on the last row alone read as a gap,
        # drawn_20261207_25: 1 px for 72 px, touching)
        g = ndimage.median_filter(hit, size=_GAP_ROWS, mode="reflect")
        mid = start + side * 0.5 * np.minimum(g, length)
        mid = np.where(np.isfinite(g), mid, side * np.maximum(side * mid, side * (self.bounds[j] + dx)))
        # (on the first frame's rows; the rows outside the scanned ones keep the half-way column)
        out = np.interp(np.arange(n_rows) + dy, rows, mid, left=self.bounds[j] + dx, right=self.bounds[j] + dx) - dx
        least = float(np.min(g)) if g.size else np.inf
        if not np.isfinite(least) and length.size:  # (nothing seen up to the wall or the reach: at least that far)
            least = float(np.min(length))
        return least, out

    def _change(self, frame, points, directions, offsets, dx, dy):
        """The change (this frame minus the first frame moved by the drift, over the local light) along
        transects in the view (``(x, y)`` points, directions, offsets: :func:`sample_transects`), smoothed along
        them by a Gaussian of ``_SMOOTH`` px; 0 outside the frame (:func:`change_transects`)."""
        step = abs(float(offsets[1] - offsets[0])) if len(offsets) > 1 else 1.0
        return change_transects(frame, self.k, self._flat, self._bg, points, directions, offsets, (dx, dy),
                                _SMOOTH / step)

    def _noise(self, sample, w, clipped_base=False):
        """Noise of the change in the water above the top face (scaled MAD over ``_NOISE_ROWS`` horizontal
        transects across the view, sampled every ``_NOISE_STEP`` px, every other one from half a px on; the
        dome, a minority of the samples, included), at most ``_NOISE_TOP_FACTOR`` times that of the
        ``_NOISE_TOP_ROWS`` rows highest above the top face (a dome over most of the rows); never below 1e-4
        (the first frame is its own reference and changes by nothing); the light's tilt; the tilt's change
        across the view (the plane's, over the view's width and height).

        The tilt: a plane through the same samples (:func:`_light_plane`),
        the light's change since the first frame across the view (a lamp, a
        window).  When dividing it out leaves the noise under ``1 /
        _TILT_NOISE`` of what it was, the tilt is returned and the noise is
        that of the change without it; else None and the noise as it was (a
        frame whose light did not change reads as before).  Measured: a tilt of
        +-10 % at the field's sides by the last of 9 frames raised the noise
        of the halo look from 0.010 to 0.075, and frames 6-8 of 6 of the 12
        presets read no dome (``dome_contrast``).  With ``clipped_base`` (the
        base's rows, whose light's gain was read, hold light the camera
        clipped), the plane is also taken off when its level over the water
        and the change of the rows highest above the top face stand over
        ``_LEVEL_NOISE`` times the noise off 0 (the noise, a MAD, does not
        see a level).
        """
        rows = np.linspace(2.0, max(w.top_row - 5.0, 10.0), _NOISE_ROWS)
        starts = 0.5 * (np.arange(_NOISE_ROWS) % 2)  # (columns)
        cols = np.arange(0.0, self.view_shape[1] - 1.5, _NOISE_STEP)
        v = sample(np.column_stack((starts, rows)), np.tile([1.0, 0.0], (rows.size, 1)), cols, own=False)

        def noise(v):
            top = v[:_NOISE_TOP_ROWS]  # (the rows highest above the top face: the last a dome reaches)
            return max(min(_mad(v), _NOISE_TOP_FACTOR * _mad(top)), 1e-4)

        at = cols[None, :] + starts[:, None]
        raw, plane = noise(v), _light_plane(v, at, rows, exclude=self._near_last_dome(w, rows, at))
        if plane is None:
            return raw, None, 0.0
        tilt = float(abs(plane[1]) * self.view_shape[1] + abs(plane[2]) * self.view_shape[0])
        # (the plane's level over the water: a change of the whole view's light the base's gain did not take off,
        # its rows clipped, which the noise, a MAD, does not see: drawn_20261207_62, its exposure up 39 % and its
        # base clipped, read a gain of 1.04-1.08 for 1.10-1.39 and the water 9-14x the noise brighter than the
        # first frame, taken for a neighbour's dome: touching)
        level = float(plane[0] + plane[1] * np.mean(at) + plane[2] * np.mean(rows))
        top = float(np.median(v[:_NOISE_TOP_ROWS]))  # (the rows highest above the top face: a dome's inside, a dyed
        # liquid over most of the rows, is not a change of the light: ho_blind_1206e)
        shifted = clipped_base and min(abs(level), abs(top)) > _LEVEL_NOISE * raw and level * top > 0.0
        if tilt <= 2.0 * raw and not shifted:  # (a spread of range T adds T**2 / 12 to the variance: 1.15x the
            # noise at T = 2 noise)
            return raw, None, tilt
        grid = plane[0] + plane[1] * at + plane[2] * rows[:, None]
        flat = noise((v - grid) / (1.0 + grid))
        return (flat, plane, tilt) if shifted or raw > _TILT_NOISE * flat else (raw, None, tilt)

    def _near_last_dome(self, w, rows, cols):
        """Which of the samples at view ``rows`` (one a row of ``cols``) lie within ``_DOME_ZONE_PX`` of the last ok
        frame's dome, columns and height (None before a dome was read): the light's plane is fitted without
        them (measured on absorbing_band, whose dyed film is a dark band along the dome, long over its top: with
        them, the plane through the water's change of frames in unchanged light read a tilt of 0.15-0.26 from
        Vtilde 1 on, and with the light's gradient drifting by 0.25 across the rows 0.92 for 0.62, its last frames
        8-11x off)."""
        if self.prev is None or self.prev.u is None or not np.size(self.prev.u):
            return None
        u, z = np.asarray(self.prev.u, float), np.asarray(self.prev.z, float)
        out = np.zeros(cols.shape, bool)
        for i, r in enumerate(rows):
            high = z >= w.top_row - r - _DOME_ZONE_PX
            if high.any():
                out[i] = ((cols[i] >= w.axis_col + u[high].min() - _DOME_ZONE_PX)
                          & (cols[i] <= w.axis_col + u[high].max() + _DOME_ZONE_PX))
        return out

    def _rays(self, sample, w):
        phis = np.linspace(_RAY_MIN, np.pi - _RAY_MIN, _N_RAYS)
        rows, cols = self.view_shape
        tmax = float(np.hypot(max(w.axis_col, cols - w.axis_col), w.top_row))
        t = np.arange(tmax, 0.0, -_SEARCH_STEP)
        centre = np.tile([w.axis_col, w.top_row], (phis.size, 1))
        v = sample(centre, np.c_[np.cos(phis), -np.sin(phis)], t)
        return phis, t, v

    def _outer_face(self, sample, w, noise):
        """Outer-face points (u, z) from the rays (px from the axis and the top face), or None; figures."""
        phis, t, v = self._rays(sample, w)
        extreme = v[np.arange(v.shape[0]), np.argmax(np.abs(v), axis=1)]
        strength = np.abs(extreme)
        if np.median(strength) < 10.0 * noise:
            return None, None, {"dome_contrast": float(np.median(strength) / max(noise, 1e-12))}
        if self.polarity == 0:  # the dome's sign is learned from the first frame that shows it, then kept
            self.polarity = int(-np.sign(np.median(np.sign(extreme[strength > 10.0 * noise]))))  # +1: darker
        sign = -float(self.polarity)
        te, found, jump, thr, figs = _first_edges(v, t, sign, noise)
        foreign = _in_front(np.clip(sign * v, 0.0, None) > thr, phis, t, (w.axis_col, w.top_row),
                            self.view_shape[1], _FRONT_L0 * self.l0)
        if foreign is not None:  # (each ray's first edge behind what lies in front of the dome)
            te, found, jump, _, more = _first_edges(np.where(foreign, 0.0, v), t, sign, noise)
            figs["edge_sign"] = more["edge_sign"]
        good = found & ~jump
        if good.sum() < 20:
            figs.update({"edge_jumps": float(jump.mean()), "edge_lost": float(1.0 - found.mean())})
            return None, None, figs
        u, z = te[good] * np.cos(phis[good]), te[good] * np.sin(phis[good])
        # second pass: along the normals of that curve at even arc length (the rays crowd at a flat dome's
        # pole and leave its rims bare)
        u, z, more = self._along_normals(sample, w, u[::-1], z[::-1], sign, thr)  # left rim -> right rim
        figs.update(more)
        return u, z, figs

    def _tracked(self, sample, w, noise):
        """Outer-face points (u, z) found along the normals of the last ok frame's outer face moved on by its last
        step, or None when they are not all there (the full search then runs); figures.

        One pass first (:meth:`_one_pass`); when the prediction is off by more
        than its reach, two: within ``_TRACK_REACH`` px along the normals of
        the last frame's points' spline every ``_TRACK_STATIONS`` px, then
        :meth:`_along_normals` of the curve found.
        """
        sign = -float(self.polarity)
        u, z, figs = self._one_pass(sample, w, noise, sign)
        if u is not None:
            self.one_pass += 1
            return u, z, figs
        (u0, z0), before = self._track[-1], (self._track[0] if len(self._track) == 2 else None)
        spl = self._spline(w, u0, z0, _FIRST_SIGMA)
        before = None if before is None else self._spline(w, *before, _FIRST_SIGMA)
        xy, nu, nz, offs, v = self._normals(sample, w, spl, _TRACK_REACH, station_step=_TRACK_STATIONS,
                                            step=_RAY_STEP, before=before, foot_step=None)
        o, found, jump, thr, figs = _first_edges(v, offs, sign, noise)
        good = found & ~jump
        near_end = found & (np.abs(o) > _TRACK_REACH - 2.0)  # (the edge may lie past the reach)
        if (figs["dome_contrast"] < 10.0 or good.mean() < 1.0 - _LOST_FLAG or near_end.mean() > 0.02
                or good.sum() < 20):
            return None, None, figs
        u, z = xy[good, 0] + o[good] * nu[good], xy[good, 1] + o[good] * nz[good]
        u, z, more = self._along_normals(sample, w, u, z, sign, thr)
        if more["edge_jumps"] > _JUMP_FLAG or more["edge_lost"] > _LOST_FLAG:  # (a track in doubt: search)
            return None, None, figs
        figs.update(more)
        return u, z, figs

    def _one_pass(self, sample, w, noise, sign):
        """Outer-face points (u, z) along the normals of the last ok frame's curve (feet at the rim) moved on by its
        last step (stations every ``_STATION_STEP`` px, ``_FOOT_STEP`` near the feet, within ``_NORMAL_REACH`` px,
        every ``_NORMAL_STEP`` px), or
        None when the prediction is in doubt (an edge near the reach's ends, contrast, jumps or losses); figures.

        An edge further than ``_JUMP_PX`` from the running median of the
        stations' within ``_ONE_PASS_MEDIAN_PX`` of arc jumped (the offsets
        from a good prediction are small and smooth along the curve).
        """
        last, before = self._curves[-1], (self._curves[0] if len(self._curves) == 2 else None)
        xy, nu, nz, offs, v = self._normals(sample, w, last, _NORMAL_REACH, before=before)
        size = 2 * int(0.5 * _ONE_PASS_MEDIAN_PX / _STATION_STEP) + 1
        o, found, jump, thr, figs = _first_edges(v, offs, sign, noise, size=size)
        near_end = found & (np.abs(o) > _NORMAL_REACH - 2.0)  # (the edge may lie past the reach)
        # (a station within 2 _FOOT_PX of the top face may: the curve's feet are bridged by the spline, the
        # prediction is poorest there; it is dropped)
        if figs["dome_contrast"] < 10.0 or np.any(near_end & (xy[:, 1] > 2.0 * _FOOT_PX)) or found.sum() < 20:
            return None, None, figs
        u, z, more = self._edges(w, xy, nu, nz, o, found, jump | near_end)
        if more["edge_jumps"] > 0.5 * _JUMP_FLAG or more["edge_lost"] > 0.5 * _LOST_FLAG:
            return None, None, figs
        figs.update(more)
        return u, z, figs

    def _feet(self, w, u, z):
        """The outer face's points with its feet on the top face at the rim, left rim -> right rim."""
        return np.column_stack((_ends(w.left - w.axis_col, u, w.right - w.axis_col), _ends(0.0, z, 0.0)))

    def _normals(self, sample, w, spl, reach, station_step=_STATION_STEP, step=_NORMAL_STEP, before=None,
                 foot_step=_FOOT_STEP):
        """Stations every ``station_step`` px along the curve ``spl`` (a :class:`ProfileSpline` with its feet;
        every ``foot_step`` px near them, :func:`_station_arcs`) and the change along their normals within
        ``reach`` px (outside -> inside, every ``step`` px): ``(xy, nu, nz, offsets, profiles)``.

        ``before``: the curve one frame earlier (a :class:`ProfileSpline`);
        each station is then moved on along its normal by its distance from it
        (the dome keeps its pace: a prediction of the next frame's curve).
        That distance is read to the point of ``before`` at the same fraction
        of its length, along the station's normal: off by the curvature times
        half the square of how far the two points lie apart along the curve
        (a hundredth of a px for 3 px at a radius of 300 px).
        """
        s = _station_arcs(spl.length, station_step, foot_step)
        xy = spl(s)
        tang = spl.tangent(s)
        nu, nz = -tang[:, 1], tang[:, 0]  # outward
        if before is not None:
            q = before(s * (before.length / spl.length))
            lead = (xy[:, 0] - q[:, 0]) * nu + (xy[:, 1] - q[:, 1]) * nz
            xy = xy + lead[:, None] * np.column_stack((nu, nz))
        offs = np.arange(reach, -reach - 1e-9, -step)  # outside -> inside
        v = sample(np.column_stack((w.axis_col + xy[:, 0], w.top_row - xy[:, 1])), np.column_stack((nu, -nz)), offs)
        return xy, nu, nz, offs, v

    def _spline(self, w, u, z, sigma):
        """The smoothing spline (scatter ``sigma``) through the outer-face points ``(u, z)`` with their feet at
        the rim; the last three kept (a frame tracked in two passes fits the last two frames' points, and the
        one before's was fitted a frame earlier when that frame took two passes too)."""
        for cu, cz, cs, spl in self._splines:
            if cu is u and cz is z and cs == sigma:
                return spl
        spl = smooth_profile(self._feet(w, u, z), sigma=sigma)
        self._splines = self._splines[-2:] + [(u, z, sigma, spl)]  # (this frame's three)
        return spl

    def _along_normals(self, sample, w, u, z, sign, thr):
        """Outer-face edges along the normals of the curve through ``(u, z)`` (stations :func:`_station_arcs`);
        figures.

        A station whose edge lies more than ``_JUMP_PX`` off the first curve
        jumped (another fringe, dust) and is dropped.
        """
        xy, nu, nz, offs, v = self._normals(sample, w, self._spline(w, u, z, _FIRST_SIGMA), _NORMAL_REACH)
        prof = np.clip(sign * v, 0.0, None)
        window = int(12.0 / _NORMAL_STEP)
        edge = outer_edges(prof, float(thr), window)
        o = np.interp(edge, np.arange(offs.size), offs, left=np.nan, right=np.nan)
        found = np.isfinite(o)
        return self._edges(w, xy, nu, nz, o, found, found & (np.abs(o) > _JUMP_PX))

    def _edges(self, w, xy, nu, nz, o, found, jump):
        """The outer face's points ``(u, z)`` at offsets ``o`` along the stations' normals (those found and not
        jumped, above the feet) and the figures ``edge_jumps``, ``edge_lost`` (shares of the curve's stations,
        each weighted by its share of the curve), ``gap_length`` (the longest run of stations without an edge,
        px of arc / l0), ``field_margin`` and ``low_dome``."""
        good = found & ~jump
        arc = _station_shares(xy)  # (each station's share of the curve, px: the stations are denser at the feet)
        # the dome reaching the field's edge: part of it is not in the frame
        cols, rows = w.axis_col + xy[:, 0], w.top_row - xy[:, 1]
        margin = float(np.min([cols.min(), self.view_shape[1] - 1 - cols.max(), rows.min()]))
        figs = {"edge_jumps": float(arc @ jump / arc.sum()), "edge_lost": float(arc @ ~found / arc.sum()),
                "gap_length": float(longest_run(~found, arc) / self.l0), "field_margin": margin}
        og = o[good]
        u, z = xy[good, 0] + og * nu[good], xy[good, 1] + og * nz[good]
        # the feet: within _FOOT_PX of the top face the dome's edge merges with the flat film's lines; the
        # spline bridges from the rim to the first points above (a dome not yet that high is flagged)
        high = z > _FOOT_PX
        figs["low_dome"] = float(np.max(z)) if z.size else 0.0
        if high.sum() >= 20:
            u, z = u[high], z[high]
        return u, z, figs

    def _flat_or_gone(self, sample, w, noise, g, out):
        """A frame without a dome edge: the flat film (volume 0) if its faces are where they were, else gone.

        Where they were: on vertical transects across the film over the well
        (its middle 80 %), the change is under 10x the noise (else gone:
        ``no_membrane``), and the faces keep over :data:`_FACES_KEPT` of the
        contrast the same film's faces keep beside the well
        (:meth:`_faces_kept`; that, taken as at least :data:`_FACES_KEPT`:
        light that took more of every face's contrast leaves too little to
        tell flat from gone); else ``poor_fit`` (``dome_contrast``).  The
        first test alone read a dome not seen as flat and ok when the faces
        are faint against the frame's noise (measured: stray light 4-29x the
        dim held-out 1206e's own light, added over a day, left the dome's
        contrast 5-8x the noise: 8 frames flat and ok, 33x the tolerance; its
        faces over the well keep -0.03 to 0.02 of their contrast, beside it
        0.03-0.18).  The flat frames (Vtilde 0) of 8 looks under 7 changes of
        the light (1.3x and 1.6x, 0.3 and 0.5 of full scale added, a ramp,
        dimming under stray light) keep over and beside the well alike,
        within 0.13 (median 0.01); this test flags 2 of 102, 85-87 % of their
        pixels clipped, 0.12-0.21 kept beside the well.
        """
        cols = np.arange(int(w.axis_col - 0.8 * w.rim_radius), int(w.axis_col + 0.8 * w.rim_radius), dtype=float)
        r0, r1 = int(w.top_row - 3), int(w.base_row + 4)
        v = sample(np.c_[cols, np.full_like(cols, r0)], np.tile([0.0, 1.0], (cols.size, 1)),
                   np.arange(0.0, r1 - r0, 0.5))
        moved = float(np.median(np.max(np.abs(v), axis=1)))
        out.figures["dome_contrast"] = out.figures.get("dome_contrast", 0.0)
        if moved > 10.0 * noise:  # the film's faces changed but no dome rose: no membrane over the well
            out.message = "no dome edge, and the flat film's faces over the well are gone"
            out.flag, out.flag_figure, out.flag_value = "no_membrane", "dome_contrast", out.figures["dome_contrast"]
            return out
        over, beside = self._faces_kept(sample, w, out.drift)
        kept = over / max(beside, _FACES_KEPT) if np.isfinite(beside) else over  # (beside: none seen in the view)
        if kept < _FACES_KEPT:  # (faint against this frame's noise, but gone)
            out.message = (f"no dome edge found (its contrast {out.figures['dome_contrast']:.1f}x the noise), but "
                           f"the flat film's faces over the well keep {over:.2f} of their first frame's contrast "
                           f"({beside:.2f} beside the well): its dome was not seen, or the membrane is gone")
            out.flag, out.flag_figure, out.flag_value = "poor_fit", "dome_contrast", out.figures["dome_contrast"]
            return out
        rim = w.rim_radius
        u = np.linspace(-rim, rim, 201)
        out.u, out.z = u, np.zeros_like(u)
        out.points_u, out.points_z = out.u, out.z
        out.residual_rms = 0.0
        out.volume_left = out.volume_right = 0.0
        out.area_left = out.area_right = np.pi * rim**2  # (each half doubled, as revolution_measures)
        out.height = 0.0
        out.figures.update({"residual_rms": 0.0, "volume_disagreement": 0.0, "gap_length": 0.0,
                            "edge_jumps": 0.0, "edge_lost": 0.0})
        out.flag, out.flag_figure, out.flag_value = self._flag(out.figures)
        out.ok, out.mode, out.geometry = True, "flat", g
        return out

    def _faces_kept(self, sample, w, drift):
        """The share of their first frame's contrast the flat film's faces keep over the well (the middle 80 %)
        and beside it (from 0.2 to 0.5 rim radii outside each rim, within the view and this chamber's columns):
        ``1 -`` the least-squares share, along vertical transects across the film, of the change ``(light - first
        frame) / light`` (the change were the faces gone) in this frame's change.

        Light added since the first frame (stray light) is divided out as a
        gain and takes a share of every face's contrast: the faces beside the
        well, where no dome rises, tell how much."""
        r0, r1 = int(w.top_row - 3), int(w.base_row + 4)
        offsets = np.arange(0.0, r1 - r0, 0.5)
        light = np.ascontiguousarray(np.rot90(self._bg, -self.k))  # (stored orientation, as a frame)
        lo, hi = 0.0, self.view_shape[1] - 1.0
        if self.bounds is not None:
            lo, hi = max(lo, self.bounds[0] + drift[0]), min(hi, self.bounds[1] + drift[0])
        rim, axis = w.rim_radius, w.axis_col
        over = np.arange(axis - 0.8 * rim, axis + 0.8 * rim)
        beside = np.concatenate((np.arange(axis - 1.5 * rim, axis - 1.2 * rim),
                                 np.arange(axis + 1.2 * rim, axis + 1.5 * rim)))
        kept = []
        for cols in (over, beside[(beside >= lo) & (beside <= hi)]):
            if cols.size < 10:
                kept.append(np.nan)
                continue
            points, directions = np.c_[cols, np.full_like(cols, r0)], np.tile([0.0, 1.0], (cols.size, 1))
            v = sample(points, directions, offsets, own=False)
            faces = change_transects(light, self.k, self._flat, self._bg, points, directions, offsets, drift,
                                     _SMOOTH / 0.5)
            v, faces = v - v.mean(axis=1)[:, None], faces - faces.mean(axis=1)[:, None]  # (a light added: 0)
            kept.append(1.0 - float(np.sum(v * faces) / max(float(np.sum(faces * faces)), 1e-30)))
        return kept[0], kept[1]

    def _finish(self, u, z, w, g, out):
        rim_l, rim_r = w.axis_col - w.left, w.right - w.axis_col
        # the outer face through its points only: the rim is a point of the mid-surface, and the outer face meets
        # the top face about (l/2) tan(beta/2) outside it (beta: the angle the film leaves the rim at; 3-27 px on
        # the reference chamber from Vtilde 0.2 to 4); a curve forced through the rim cuts a wedge out of the dome
        # beside it (-0.1..-0.3 % of the volume there, about 4x that on a chamber of half the radius)
        # (its scatter: at least _FACE_SIGMA, else the points' own, so a noisy trace is not followed into loops)
        try:
            face = smooth_profile(np.column_stack((u, z)), sigma=max(_FACE_SIGMA, _scatter(u, z)))
        except ValueError as err:  # (fewer than 4 distinct points)
            out.message = f"too few outer-face points: {err}"
            out.flag, out.flag_figure, out.flag_value = "poor_fit", "edge_lost", out.figures.get("edge_lost", np.nan)
            return out
        s, xy = face.sample(step=1.0)
        resid = float(np.sqrt(np.nanmean(face.normal_residuals**2)))
        tang = face.tangent(s)
        out.figures["least_bend"] = _least_bend(xy, max(self.l0, _BEND_CHORD_PX))
        normal = np.column_stack((-tang[:, 1], tang[:, 0]))  # outward for a curve left rim -> over the top -> right rim
        l0, rim = self.l0, 0.5 * (rim_l + rim_r)
        # the film's thickness along the curve: uniform first, then from the kinematics of the last mid-surface,
        # which is bridged from its last point to the rim; the film over the well is the first frame's (the rim's
        # widening, lambda_pre, stretches it and adds none)
        lthick = np.full(len(xy), l0)
        for _ in range(3):
            mid = xy - 0.5 * lthick[:, None] * normal
            mu, mz = mid[:, 0], mid[:, 1] + 0.5 * l0
            lthick = _thickness(_ends(-rim_l, mu, rim_r), _ends(0.0, np.maximum(mz, 0.0), 0.0), *self._rim0,
                                l0)[1:-1]
        keep = mz > 0.0  # (the third mid-surface above the rim plane, from rim to rim)
        mu, mz = _ends(-rim_l, mu[keep], rim_r), _ends(0.0, mz[keep], 0.0)
        try:
            m = revolution_measures(mu, mz)
        except ValueError as err:
            out.message = str(err)
            out.flag, out.flag_figure, out.flag_value = "poor_fit", "residual_rms", float(resid)
            return out
        out.u, out.z = mu, mz
        out.points_u, out.points_z = u, z + 0.5 * l0
        out.residual_rms = float(resid)
        out.volume_left, out.volume_right = m.volume_left, m.volume_right
        out.area_left, out.area_right = m.area_left, m.area_right
        out.height = m.height
        floor = 5.0 * np.pi * rim**2
        out.figures.update({"residual_rms": float(resid), "film_thickness": float(np.min(lthick)),
                            "volume_disagreement": float(abs(m.volume_left - m.volume_right) /
                                                         max(abs(m.volume), floor))})
        carried = self._still_touching(out.figures, m.volume)
        out.flag, out.flag_figure, out.flag_value = self._flag(out.figures)
        if out.flag_figure == "neighbour_gap":
            self._touched = (out.index, out.flag_value, m.volume)
            if carried is not None:
                out.message = (f"the domes came within {carried[1]:.1f} px in frame {carried[0]} and this dome has "
                               f"grown since: growing domes do not part (the gap measured here: {carried[2]:.1f} "
                               f"px, a neighbour's face met and taken for the water's edge)")
        if out.flag_figure == "field_margin":
            out.message = field_edge_message(out.flag_value)
            if self._side_seen is not None:  # (a neighbour's dome met: the trace runs on along it)
                out.message += (f"; a dome has come in at the field's side since frame {self._side_seen}: the "
                                "domes may touch")
        elif out.flag_figure == "least_bend":
            out.message = (f"a straight stretch in the dome's outline (its least bend over a tenth of it "
                           f"{out.flag_value:.2f} of its mean, under {_BEND_FLAG:g}): a membrane under pressure "
                           f"bends everywhere; a cap torn off, or another edge followed")
        out.ok, out.mode = True, "silhouette"
        if out.flag == "ok":
            self.prev = out
            # (the next frame's outer face is searched along the normals of this one's, moved on by as much as it
            # moved since the last, on a curve from rim to rim as the stations are: this face sampled every px, its
            # ends carried down to the top face (:func:`_foot`: straight to the rim instead, the feet's normals
            # point into the base and the face's lowest points creep up frame by frame), then on to the rim)
            track = _Polyline(np.vstack(([-rim_l, 0.0], _foot(xy[0], -tang[0]), xy, _foot(xy[-1], tang[-1]),
                                         [rim_r, 0.0])))
            self._track = ((self._track[-1],) if self._track else ()) + ((u, z),)
            self._curves = ((self._curves[-1],) if self._curves else ()) + (track,)
        else:
            self._track = self._curves = None
        return out

    def _still_touching(self, fig, volume):
        """After a frame whose dome came within the touching flag of a neighbour's (:attr:`_touched`), this
        frame's ``neighbour_gap`` in ``fig`` is that frame's gap unless its dome lost more than
        ``1 - _PARTED_VOLUME`` of that frame's ``volume``: two domes that grow do not part.  Returns ``(frame,
        gap, measured)`` when the gap was carried so, else None.

        Found on drawn_20261207_111 rendered without its drawn focus and light
        drift and stamp (domes overlapping, the view turned a quarter, 2 um/px;
        in full it reads touching as the truth): frames 5, 6 and 8 flagged
        touching, frame 7 read its gap 16 px and ok, its rim in clipped light
        0.5 % off (silent).
        Once the domes overlap the gap is measured from this dome's face to
        the next face beyond it, the neighbour's far side, and the touching
        flag rests on the face cut off at the search's limit
        (:meth:`_cut_at_limit`), which a tenth of a px decides.
        """
        if self._touched is None or "neighbour_gap" not in fig:
            return None
        index, gap, before = self._touched
        measured = fig["neighbour_gap"]
        if not volume >= _PARTED_VOLUME * before or not measured > gap:
            return None
        fig["neighbour_gap"] = gap
        return index, gap, measured

    def _flag(self, fig):
        st = self.settings
        fig.setdefault("flat_film", self.film_mismatch)
        fig.setdefault("flat_lift", self.flat_lift)
        checks = [
            # (first: a stretch of the dome outside the frame is no tear, and a neighbour is not seen there)
            ("poor_fit", "field_margin", fig.get("field_margin", np.inf) < FIELD_MARGIN_PX),
            # (then a first frame that is not flat: every change, and each event seen in it, is measured from it)
            ("poor_fit", "flat_lift", abs(self.flat_lift) > _FLAT_LIFT_PX),
            ("touching", "neighbour_gap", fig.get("neighbour_gap", np.inf) < st.touching_flag),
            ("delaminated", "rim_contact", fig.get("rim_contact", np.nan) < st.delamination_flag),
            ("fractured", "gap_length", fig.get("gap_length", 0.0) > st.gap_flag),
            ("poor_fit", "wall_misfit", fig.get("wall_misfit", 1.0) > _SHIFT_WORSE),
            ("poor_fit", "least_bend", fig.get("least_bend", np.nan) < _BEND_FLAG),
            ("poor_fit", "flat_film", self.film_mismatch > max(_FILM_TOL_PX, _FILM_TOL * self.l0)),
            ("poor_fit", "low_dome", fig.get("low_dome", np.inf) < _LOW_DOME_PX),
            ("poor_fit", "edge_lost", fig.get("edge_lost", 0.0) > _LOST_FLAG),
            ("poor_fit", "edge_jumps", fig.get("edge_jumps", 0.0) > _JUMP_FLAG),
            ("poor_fit", "residual_rms", not fig["residual_rms"] <= st.residual_flag),
            ("poor_fit", "volume_disagreement", fig.get("volume_disagreement", 0.0) > st.asymmetry_flag),
        ]
        return first_flag(checks, fig)

    def _from_points(self, frame, g, out, manual):
        """A manual profile (stored-frame ``(x=col, y=row)`` px) replaces the trace."""
        out.points_u, out.points_z, out.u, out.z = manual_curve(FrameView(frame, self.k), g.line, manual)
        out.source = "manual"
        out.residual_rms = 0.0
        m = revolution_measures(out.u, out.z)
        out.volume_left, out.volume_right = m.volume_left, m.volume_right
        out.area_left, out.area_right = m.area_left, m.area_right
        out.height = m.height
        out.figures.update({"residual_rms": 0.0})
        out.flag, out.flag_figure, out.flag_value = "ok", "", np.nan
        out.ok = True
        return out
