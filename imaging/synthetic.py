r"""Synthetic cross-section micrographs of bulging chambers, with ground truth.

The renderer draws what the microscope sees of a cut device imaged edge-on
(main text Sec. 2.3, Fig. 1), from the model's bulge profiles
(:func:`osmobulge.modeling.bulge_profile`, main text Eqns 17-24):

* the elastomer **base** (one grey level) fills the lower part of the field;
* the **well**, a cavity of depth ``h`` filled with salt solution, is cut into
  its top surface.  Its half-width is ``a`` at the bottom and
  ``a * lambda_pre(Vtilde)`` at the top: the walls are straight lines that lean
  outwards as the rim widens (supplement Sec. 5.7, Fig. S6); with
  ``lambda_pre = 1`` the well is a rectangle;
* the **membrane**, a band of local thickness ``l0 * thickness_ratio`` seen
  edge-on, lies on the top surface outside the rim (thickness ``l0``) and
  rises over the well into the dome.  Its midline is the ground truth: the
  flat midline is the rim plane ``z = 0`` and the dome midline is the model
  profile ``(a r(rho), a z(rho))``, its foot at the rim radius
  ``a * lambda_pre``.  Beyond :math:`\tilde V = 2/3` the dome overhangs its rim;
* **water** above (background level) and salt solution inside the dome.

Edges are rasterised by exact area coverage (:mod:`osmobulge.imaging._raster`),
then blurred by a Gaussian point-spread function, so the intensity-weighted
centre of the membrane band across its normal is the true midline to a few
thousandths of a pixel.

Nuisances (:class:`Nuisances`) are all parameters: contrast of either sign,
uneven illumination, 8- to 16-bit output, Gaussian and Poisson noise, blur,
tilt, random-walk stage drift, dust, neighbouring chambers, frames
rendered delaminated, fractured or touching a neighbour's bulge, and a time
stamp and scale bar burned in as a microscope's export with annotations does.

Default field
-------------
``pixel_size = 1 um`` and ``shape = (1024, 1024)``: a 1.024 mm square field.
The reference chamber of the paper (``a = 200 um``, ``h = 110 um``,
``l0 = 20 um``) has its rim line (flat membrane midline) at row 840, with 64 um of base
under the well, so a PDMS dome up to the locking volume (:math:`\tilde V = 7.2`,
height 2.7 a = 538 um, overhang half-width 1.9 a = 382 um) fits with room for
drift, and the thinnest pole at :math:`\tilde V = 6` is 1.5 px thick.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np
import xarray as xr
from scipy import ndimage

from osmobulge import __version__
from osmobulge.imaging._raster import Layer, band_polygon, blurred_band, circle_polygon
from osmobulge.modeling.bulge import bulge_profiles as profiles
from osmobulge.modeling.materials import PDMS

__all__ = [
    "SceneGeometry",
    "Nuisances",
    "SyntheticSeries",
    "render_series",
    "render_frame",
    "render_simulation",
    "BULGE_DIRECTIONS",
    "FLAGS",
    "FRACTURE_MODES",
    "REFERENCE_CHAMBER",
]

BULGE_DIRECTIONS = ("up", "down", "left", "right")
FLAGS = ("ok", "delaminated", "fractured", "touching")
FRACTURE_MODES = ("gap", "collapsed")
TIME_STAMPS = ("none", "tl", "tr", "bl", "br")
BIT_DEPTHS = (8, 10, 12, 14, 16)
#: the paper's reference chamber (main text Sec. 3.1): radius, depth, membrane thickness (m)
REFERENCE_CHAMBER = (200e-6, 110e-6, 20e-6)
#: default frame interval (s): the paper images every 10-15 min (Sec. 2.3)
DEFAULT_FRAME_INTERVAL = 600.0
_DIRECTION_ANGLE = {"up": 0.0, "left": 90.0, "down": 180.0, "right": -90.0}


# --------------------------------------------------------------------------------------
# parameters
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SceneGeometry:
    """Layout and grey levels of the (nuisance-free) scene.

    Parameters
    ----------
    bulge_direction : {"up", "down", "left", "right"}
        Direction the dome grows in the image (``"up"``: towards row 0).
    axis_position : tuple of float or None, px
        ``(col, row)`` of the point where the chamber axis meets the rim line
        (the flat membrane midline) before tilt and drift.  ``None`` centres the
        axis and puts the rim line ``depth + base_margin + l0/2`` from the
        image edge behind the well.
    base_margin : float, m
        Base left below the well bottom when ``axis_position`` is ``None``.
    background_level, base_level, liquid_level, membrane_level : float
        Grey levels in [0, 1] of the water, the elastomer base, the salt
        solution (well and dome) and the membrane, for ``polarity=+1``.
    """

    bulge_direction: str = "up"
    axis_position: tuple | None = None
    base_margin: float = 64e-6
    background_level: float = 0.80
    base_level: float = 0.55
    liquid_level: float = 0.80
    membrane_level: float = 0.25

    def __post_init__(self):
        if self.bulge_direction not in BULGE_DIRECTIONS:
            raise ValueError(f"bulge_direction must be one of {BULGE_DIRECTIONS}, got {self.bulge_direction!r}")
        for name in ("background_level", "base_level", "liquid_level", "membrane_level"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and 0.0 <= v <= 1.0):
                raise ValueError(f"{name} must be a grey level in [0, 1], got {v!r}")
        if not (math.isfinite(self.base_margin) and self.base_margin >= 0):
            raise ValueError(f"base_margin must be >= 0 (m), got {self.base_margin!r}")
        if self.axis_position is not None:
            ap = tuple(float(x) for x in self.axis_position)
            if len(ap) != 2 or not all(math.isfinite(x) for x in ap):
                raise ValueError(f"axis_position must be (col, row) in px, got {self.axis_position!r}")
            object.__setattr__(self, "axis_position", ap)


@dataclass(frozen=True)
class Nuisances:
    """Every imaging imperfection of a real series, as parameters.

    The defaults are a clean 16-bit render with a 1 px Gaussian PSF.

    Parameters
    ----------
    polarity : {+1, -1}
        +1: dark membrane on a light background (bright field); -1: inverted
        contrast (every grey level ``g`` becomes ``1 - g``).
    contrast : float
        Scale of every grey level's difference from the background (1 = the
        levels of :class:`SceneGeometry`; 0.2 = a washed-out image), > 0.
    illumination_gradient : float
        Linear illumination ramp: relative brightness changes by
        ``+-illumination_gradient`` from the centre to the field edge along
        ``illumination_angle`` (0 .. 0.9).
    illumination_angle : float, deg
        Direction of the brightening, counter-clockwise from the +column axis.
    vignetting : float
        Relative darkening at the field corners, quadratic in the distance from
        the centre (0 .. 0.9).
    bit_depth : {8, 10, 12, 14, 16}
        Output grey range ``0 .. 2**bit_depth - 1``; uint8 for 8, uint16 otherwise.
    noise_sigma : float
        Gaussian (read) noise, standard deviation as a fraction of full scale.
    poisson_photons : float
        Photons collected at full scale for shot noise (0: none); noise is
        ``Poisson(I * poisson_photons) / poisson_photons``.
    blur_sigma : float, px
        Gaussian point-spread function (0: none).
    tilt : float, deg
        Rotation of the device in the image, counter-clockwise as displayed,
        about the axis point.
    drift_sigma : float, px
        Stage drift: random walk with this step standard deviation per frame
        in both directions (frame 0 undrifted).
    drift : array_like of shape (T, 2) or None, px
        Explicit (column, row) offset of every frame; overrides ``drift_sigma``.
    exposure_sigma : float
        The lamp or the exposure changing between frames: every frame after
        the first has its light scaled by ``1 + exposure_sigma * N(0, 1)``
        (at least 0.3, at most 2), independently; the truth's ``light_gain``.
    exposure_drift : float
        The exposure (or the lamp) turned up over the series: frame ``i``'s
        light times ``1 + exposure_drift (t_i - t_0)/(t_last - t_0)`` (with
        ``exposure_sigma``'s); light over the full scale clips there, as a
        camera's does (-0.9 .. 3); the truth's ``light_gain``.
    dust_count : int
        Dust specks on the optics (fixed in the camera frame).
    dust_radius : tuple of float, px
        Range of the specks' Gaussian radii.
    dust_opacity : float
        Peak light absorbed by a speck (0 .. 1).
    neighbours : tuple of (offset, vtilde_scale)
        Other chambers in the field: ``offset`` (m) of their axis along the
        rim line from the reference chamber's (positive towards +column for
        ``bulge_direction="up"``), and the ratio of their dimensionless volume
        to the reference chamber's in every frame.  Same radius, depth,
        membrane and pre-stretch law.
    delaminated_frames, fractured_frames, touching_frames : tuple of int
        Frame indices rendered with the membrane lifted off the top surface
        near the rim, torn, or pressed against a neighbour's bulge (disjoint).
    delamination_length : float
        Lifted length outside each rim, as a fraction of ``a``.
    delamination_gap : float
        Height of the lifted membrane above the top surface at the rim, in
        units of ``l0`` (the dome is lifted by the same amount).
    fracture_mode : {"gap", "collapsed"}
        "gap": a piece of the dome is missing; "collapsed": the dome is gone
        and two torn flaps hang from the rims into the well.
    fracture_gap : float
        Length of the missing piece as a fraction of the dome's arc length.
    time_stamp : {"none", "tl", "tr", "bl", "br"}
        Annotations burned into every frame, as a microscope's export with
        annotations writes them: the time since the first frame
        (``hh:mm:ss.000  t = m min``, white: the bit depth's full scale, a
        28th of the frame's height, 10 px from the edges) in that corner of
        the stored image, its digits changing from frame to frame, and a
        100 um scale bar with its label in the other bottom corner (the bottom
        right for a stamp on the left).
    focus_drift : float, m
        The focal plane's travel from the first frame to the last, linear in
        time (a microscope's focus drifting over a day without autofocus):
        frame ``i`` is rendered with ``optics.defocus + focus_drift (t_i -
        t_0)/(t_last - t_0)``.  Optics only.
    debris : int
        Particles drifting in the water in front of the device, this many in
        every frame after the first (none in the flat first frame): each a
        blurred dark disc as a dust speck is (radius drawn from
        ``debris_radius``, px, its opacity up to ``dust_opacity``), at a new
        place in every frame, anywhere in the field (a stream of its own: the
        other draws are as without it).  Their places are the truth's
        ``debris`` attr.
    debris_radius : tuple of float, px
    light_drift : float
        The illumination's gradient changes by this much from the first frame
        to the last, linear in time, along ``illumination_angle`` (a lamp, a
        condenser or a window warming one side of the field over a day): frame
        ``i``'s gradient is ``illumination_gradient + light_drift (t_i -
        t_0)/(t_last - t_0)`` (-0.9 .. 0.9 each).
    stray_light : float
        Light added to the image (a window, the room's lamps; a fraction of
        full scale), growing linearly in time from none in the first frame to
        this much in the last at the side of the field ``illumination_angle``
        points to, none at the other (``stray_light (t_i - t_0)/(t_last - t_0)
        (1 + s)/2``, ``s`` the position along the angle, -1 .. 1 from the
        field's centre to its side); before the noise (0 .. 1).
    """

    polarity: int = 1
    contrast: float = 1.0
    illumination_gradient: float = 0.0
    illumination_angle: float = 0.0
    vignetting: float = 0.0
    bit_depth: int = 16
    noise_sigma: float = 0.0
    poisson_photons: float = 0.0
    blur_sigma: float = 1.0
    tilt: float = 0.0
    drift_sigma: float = 0.0
    drift: object = None
    exposure_sigma: float = 0.0
    exposure_drift: float = 0.0
    dust_count: int = 0
    dust_radius: tuple = (2.0, 6.0)
    dust_opacity: float = 0.5
    neighbours: tuple = ()
    delaminated_frames: tuple = ()
    fractured_frames: tuple = ()
    touching_frames: tuple = ()
    delamination_length: float = 0.3
    delamination_gap: float = 1.5
    fracture_mode: str = "gap"
    fracture_gap: float = 0.15
    time_stamp: str = "none"
    focus_drift: float = 0.0
    debris: int = 0
    debris_radius: tuple = (4.0, 12.0)
    light_drift: float = 0.0
    stray_light: float = 0.0

    def __post_init__(self):
        if self.polarity not in (1, -1):
            raise ValueError(f"polarity must be +1 (dark membrane) or -1 (inverted), got {self.polarity!r}")
        if self.bit_depth not in BIT_DEPTHS:
            raise ValueError(f"bit_depth must be one of {BIT_DEPTHS}, got {self.bit_depth!r}")
        if self.fracture_mode not in FRACTURE_MODES:
            raise ValueError(f"fracture_mode must be one of {FRACTURE_MODES}, got {self.fracture_mode!r}")
        if self.time_stamp not in TIME_STAMPS:
            raise ValueError(f"time_stamp must be one of {TIME_STAMPS}, got {self.time_stamp!r}")
        ranges = {
            "contrast": (1e-3, 10.0),
            "illumination_gradient": (0.0, 0.9),
            "vignetting": (0.0, 0.9),
            "noise_sigma": (0.0, 1.0),
            "poisson_photons": (0.0, 1e9),
            "blur_sigma": (0.0, 50.0),
            "tilt": (-45.0, 45.0),
            "drift_sigma": (0.0, 100.0),
            "exposure_sigma": (0.0, 0.5),
            "exposure_drift": (-0.9, 3.0),
            "dust_opacity": (0.0, 1.0),
            "delamination_length": (0.01, 2.0),
            "delamination_gap": (0.0, 20.0),
            "fracture_gap": (0.01, 0.9),
            "illumination_angle": (-360.0, 360.0),
            "focus_drift": (-5e-4, 5e-4),
            "light_drift": (-0.9 - self.illumination_gradient, 0.9 - self.illumination_gradient),
            "stray_light": (0.0, 1.0),
        }
        for name, (lo, hi) in ranges.items():
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"{name} must be a number in [{lo}, {hi}], got {v!r}")
        for count, radius in (("dust_count", "dust_radius"), ("debris", "debris_radius")):
            if not (isinstance(getattr(self, count), int) and getattr(self, count) >= 0):
                raise ValueError(f"{count} must be an int >= 0, got {getattr(self, count)!r}")
            dr = tuple(float(x) for x in getattr(self, radius))
            if len(dr) != 2 or not (0 < dr[0] <= dr[1]):
                raise ValueError(f"{radius} must be (min, max) px with 0 < min <= max, got {getattr(self, radius)!r}")
            object.__setattr__(self, radius, dr)
        nb = []
        for item in self.neighbours:
            try:
                off, scale = (float(x) for x in item)
            except (TypeError, ValueError):
                raise ValueError(f"neighbours must be (offset_m, vtilde_scale) pairs, got {item!r}") from None
            if not (math.isfinite(off) and off != 0 and math.isfinite(scale) and scale >= 0):
                raise ValueError(f"neighbour offset must be non-zero (m) and vtilde_scale >= 0, got {item!r}")
            nb.append((off, scale))
        object.__setattr__(self, "neighbours", tuple(nb))
        sets = {}
        for name in ("delaminated_frames", "fractured_frames", "touching_frames"):
            try:
                idx = tuple(sorted({int(i) for i in getattr(self, name)}))
            except (TypeError, ValueError):
                raise ValueError(f"{name} must be frame indices (ints), got {getattr(self, name)!r}") from None
            if any(i < 0 for i in idx):
                raise ValueError(f"{name} must be >= 0, got {idx}")
            object.__setattr__(self, name, idx)
            sets[name] = set(idx)
        names = list(sets)
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                both = sets[a] & sets[b]
                if both:
                    raise ValueError(f"{a} and {b} share frames {sorted(both)}; a frame has one event")
        if self.touching_frames and not self.neighbours:
            raise ValueError("touching_frames needs a neighbour chamber: set neighbours=((offset_m, vtilde_scale),)")
        if self.drift is not None:
            d = np.asarray(self.drift, float)
            if d.ndim != 2 or d.shape[1] != 2 or not np.all(np.isfinite(d)):
                raise ValueError(f"drift must be an array of shape (T, 2) of finite px offsets, got shape {d.shape}")

    def to_attrs(self) -> dict:
        """netCDF-safe attrs (prefixed ``nuisance_``)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "drift":
                v = "explicit" if v is not None else "random walk"
            elif f.name == "neighbours":
                v = np.asarray(v, float).ravel() if v else "none"
            elif isinstance(v, tuple):
                v = np.asarray(v, float if f.name.endswith("_radius") else np.int64) if v else "none"
            out[f"nuisance_{f.name}"] = v
        return out


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------
def _chamber_tuple(chamber):
    """(radius, depth, thickness) in m from a tuple or an object with those attributes."""
    if all(hasattr(chamber, k) for k in ("radius", "depth", "thickness")):
        vals = (chamber.radius, chamber.depth, chamber.thickness)
    else:
        try:
            vals = tuple(chamber)
        except TypeError:
            vals = ()
        if len(vals) != 3:
            raise TypeError(
                f"chamber must be (radius_m, depth_m, thickness_m) or an osmobulge.modeling Chamber, got {chamber!r}"
            )
    a, h, l0 = (float(x) for x in vals)
    for name, v in (("radius", a), ("depth", h), ("thickness", l0)):
        if not (math.isfinite(v) and 0 < v < 0.1):
            raise ValueError(f"chamber {name}={v!r} m is not a plausible length (0 < value < 0.1 m; give metres)")
    if l0 >= a:
        raise ValueError(f"chamber thickness={l0!r} m must be smaller than radius={a!r} m")
    return a, h, l0


def _check_shape(shape):
    try:
        h, w = (int(x) for x in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape must be (rows, columns), got {shape!r}") from None
    if h < 16 or w < 16:
        raise ValueError(f"shape must be at least (16, 16) px, got {shape!r}")
    return h, w


@dataclass
class _Frame:
    """Everything needed to draw one frame (physical units, scene frame)."""

    r: np.ndarray  # (M,) r/a of the reference dome, pole -> rim
    z: np.ndarray
    t: np.ndarray  # thickness ratio
    lam: float
    neighbours: list = field(default_factory=list)  # [(offset, r, z, t, lam)]
    flag: str = "ok"
    fracture_centre: float = 0.5


def _skirt(nuis, a, l0, n=48):
    """A delaminated film beyond a rim: its mid-surface's distance past the rim and height above the flat film's
    (m), ``lift (1 - s / dl)**2`` from ``lift = delamination_gap l0`` at the rim down to the top face at
    ``dl = delamination_length a`` (the painted and the optics renderers draw the same)."""
    lift, dl = nuis.delamination_gap * l0, nuis.delamination_length * a
    uu = np.linspace(0.0, dl, n)
    return uu, lift * (1.0 - uu / dl) ** 2


#: a collapsed dome's flaps hang from the rim into the well at this angle below the horizontal (rad)
_FLAP_ANGLE = math.radians(60)


def _flap_length(a, h, rim):
    """Length (m) of a collapsed dome's flaps, hanging from the rim into the well at ``_FLAP_ANGLE``."""
    return min(0.6 * a, 0.9 * h / math.sin(_FLAP_ANGLE) + 0.5 * rim)


def _torn(mid, fr, nuis):
    """The arc fraction of each point of a full midline (left rim 0 -> right rim 1) and the torn piece's ends."""
    seg = np.hypot(*np.diff(mid, axis=0).T)
    s = np.r_[0.0, np.cumsum(seg)] / seg.sum()
    return s, fr.fracture_centre - 0.5 * nuis.fracture_gap, fr.fracture_centre + 0.5 * nuis.fracture_gap


def _midline(r, z, a, uc):
    """Full dome midline (u, w) from the left rim over the pole to the right rim."""
    u = np.r_[uc - a * r[::-1], uc + a * r[1:]]
    w = np.r_[a * z[::-1], a * z[1:]]
    return np.stack([u, w], axis=1)


class _Scene:
    """Builds the polygons of a frame and rasterises them."""

    def __init__(self, a, h, l0, pixel_size, shape, scene: SceneGeometry, nuis: Nuisances):
        self.a, self.h, self.l0, self.p = a, h, l0, pixel_size
        self.shape = shape
        self.scene, self.nuis = scene, nuis
        rows, cols = shape
        self.big = 2.0 * max(rows, cols) * pixel_size
        if scene.axis_position is not None:
            self.anchor = np.array(scene.axis_position, float)
        else:
            back = (h + scene.base_margin + 0.5 * l0) / pixel_size
            self.anchor = {
                "up": np.array([cols / 2.0, rows - back]),
                "down": np.array([cols / 2.0, back]),
                "left": np.array([cols - back, rows / 2.0]),
                "right": np.array([back, rows / 2.0]),
            }[scene.bulge_direction]
        phi = math.radians(_DIRECTION_ANGLE[scene.bulge_direction] + nuis.tilt)
        self.cos, self.sin = math.cos(phi), math.sin(phi)

    def to_scene(self, cols, rows, drift=(0.0, 0.0)):
        """Inverse of :meth:`to_pixels`: fractional (col, row) px -> scene (u, w) in m."""
        x = (np.asarray(cols, float) - self.anchor[0] - drift[0]) * self.p
        y = -(np.asarray(rows, float) - self.anchor[1] - drift[1]) * self.p
        return x * self.cos + y * self.sin, -x * self.sin + y * self.cos

    def to_pixels(self, uw, drift=(0.0, 0.0)):
        """Scene (u, w) in m (w: height above the flat midline) -> (col, row) px."""
        uw = np.asarray(uw, float) / self.p
        x = uw[..., 0] * self.cos - uw[..., 1] * self.sin
        y = uw[..., 0] * self.sin + uw[..., 1] * self.cos
        return np.stack([self.anchor[0] + drift[0] + x, self.anchor[1] + drift[1] - y], axis=-1)

    # -- polygons --------------------------------------------------------------------
    def polygons(self, fr: _Frame):
        a, h, l0, big = self.a, self.h, self.l0, self.big
        nuis = self.nuis
        base, liquid, membrane = [], [], []  # lists of (poly_uw, sign)
        domes = []  # (midline_uw, half_width): drawn as blurred bands
        base.append((np.array([[-big, -0.5 * l0], [big, -0.5 * l0], [big, -big], [-big, -big]]), 1.0))
        chambers = [(0.0, fr.r, fr.z, fr.t, fr.lam, True)] + [
            (o, r, z, t, lam, False) for o, r, z, t, lam in fr.neighbours
        ]
        chambers.sort(key=lambda c: c[0])
        gaps = []  # flat membrane intervals between rims
        left_edge = -big
        lift = nuis.delamination_gap * l0 if fr.flag == "delaminated" else 0.0
        dl = nuis.delamination_length * a
        for uc, r, z, t, lam, is_ref in chambers:
            rim = a * lam
            top = -0.5 * l0
            well = np.array([[uc - rim, top], [uc + rim, top], [uc + a, top - h], [uc - a, top - h]])
            base.append((well, -1.0))
            liquid.append((well, 1.0))
            mid = _midline(r, z, a, uc)
            thick = l0 * np.r_[t[::-1], t[1:]]
            if is_ref and lift > 0:
                mid = mid + np.array([0.0, lift])
            collapsed = is_ref and fr.flag == "fractured" and nuis.fracture_mode == "collapsed"
            if not collapsed:
                interior = np.concatenate([mid, [[uc + rim, top], [uc - rim, top]]])
                liquid.append((interior, 1.0))
            if collapsed:
                t_rim = float(t[-1]) * l0
                length = _flap_length(a, h, rim)
                for sgn in (-1.0, 1.0):
                    p0 = np.array([uc + sgn * rim, 0.0])
                    d = np.array([-sgn * math.cos(_FLAP_ANGLE), -math.sin(_FLAP_ANGLE)])
                    pts = p0 + np.linspace(0, length, 24)[:, None] * d
                    membrane.append((band_polygon(pts, 0.5 * t_rim), 1.0))
            elif is_ref and fr.flag == "fractured":
                s, lo, hi = _torn(mid, fr, nuis)
                for sel in (s <= lo, s >= hi):
                    if sel.sum() >= 2:
                        domes.append((mid[sel], 0.5 * thick[sel]))
            else:
                domes.append((mid, 0.5 * thick))
            join = 0.5 * max(l0, float(thick[0]))
            membrane.append((circle_polygon(mid[0], join), 1.0))
            membrane.append((circle_polygon(mid[-1], join), 1.0))
            left_rim, right_rim = uc - rim, uc + rim
            if is_ref and lift > 0:
                uu, ww = _skirt(nuis, a, l0)
                for sgn in (-1.0, 1.0):
                    pts = np.stack([uc + sgn * (rim + uu), ww], axis=1)
                    membrane.append((band_polygon(pts, 0.5 * l0), 1.0))
                    membrane.append((circle_polygon(pts[-1], 0.5 * l0), 1.0))
                left_rim, right_rim = left_rim - dl, right_rim + dl
            gaps.append((left_edge, left_rim))
            left_edge = right_rim
        gaps.append((left_edge, big))
        for u0, u1 in gaps:
            if u1 > u0:
                membrane.append((np.array([[u0, -0.5 * l0], [u1, -0.5 * l0], [u1, 0.5 * l0], [u0, 0.5 * l0]]), 1.0))
        return base, liquid, membrane, domes

    def render(self, fr: _Frame, drift, levels, sigma):
        """Noise-free blurred float32 image in [0, 1] (before polarity, illumination, noise).

        Base, liquid and the flat membrane are rasterised by exact area
        coverage and blurred by a discrete Gaussian; the domes are drawn
        afterwards as analytically blurred bands (:func:`blurred_band`), whose
        profile across the band is symmetric about the true midline and free
        of pixel aliasing.  Without blur (``sigma < 0.5``) the domes are exact
        area coverage too.
        """
        bg, lb, ll, lm = levels
        base, liquid, membrane, domes = self.polygons(fr)
        smooth = sigma >= _MIN_ANALYTIC_SIGMA
        if not smooth:
            membrane = membrane + [(band_polygon(m, w), 1.0) for m, w in domes]
        covs = []
        for polys in (base, liquid, membrane):
            lay = Layer(self.shape)
            for poly, sign in polys:
                lay.add(self.to_pixels(poly, drift), sign)
            covs.append(lay.coverage())
        c_base, c_liq, c_mem = covs
        # area-exact mixing: base, liquid and water are disjoint; the membrane never overlaps the base
        # (it lies on it) but may overlap the liquid (dome feet, flaps), so it covers the non-base rest
        # of a pixel -- "membrane over everything" would count the water under a band's lower edge
        # on the base and shift that edge up (0.24 px at 1 px blur)
        img = np.full(self.shape, bg, np.float32)
        img += c_base * np.float32(lb - bg)
        img += c_liq * np.float32(ll - bg)
        hit = np.flatnonzero(c_mem)  # the bands only (sparse)
        cb, cl = c_base.reshape(-1)[hit], c_liq.reshape(-1)[hit]
        cm = np.minimum(c_mem.reshape(-1)[hit], 1.0 - cb)
        rest = (1.0 - cb - cm) / np.maximum(1.0 - cb, 1e-12)
        img.reshape(-1)[hit] = cb * lb + cm * lm + rest * (cl * ll + (1.0 - cb - cl) * bg)
        if sigma > 0:
            img = _blur(img, sigma)
        if smooth and domes:
            # pixel-area sampling acts as a box of variance 1/12 on top of the PSF
            sig_eff = math.sqrt(sigma**2 + 1.0 / 12.0)
            cov = np.zeros(img.size, np.float32)
            for m, w in domes:
                idx, val = blurred_band(self.shape, self.to_pixels(m, drift), w / self.p, sig_eff)
                cov[idx] = np.maximum(cov[idx], val)
            flat = img.reshape(-1)
            hit = np.flatnonzero(cov)
            flat[hit] += cov[hit] * (np.float32(lm) - flat[hit])
        return img

    def _optical_chamber(self, fr: _Frame):
        """The reference chamber for :func:`optics.optical_path`, with the frame's event drawn as the painted model
        draws it: delaminated, the dome lifted by ``delamination_gap l0`` and the film beyond each rim peeled off the
        top face over ``delamination_length a`` (a continuation of the profile down to the top face, ``l0`` thick);
        fractured, the piece of the dome the painted model leaves out (the arc ``fracture_centre +-
        fracture_gap / 2`` of the midline from the left rim) torn out of its side (:class:`optics.Hole`: its heights
        on its side, or the cap when it spans the pole); collapsed, the well open and its flaps hanging in
        (:class:`optics.Collapse`, as the painted flaps: 60 degrees, ``min(0.6 a, 0.9 h / sin 60 + rim / 2)``)."""
        from osmobulge.imaging.optics import Collapse, Hole

        a, l0, nuis = self.a, self.l0, self.nuis
        r, z, t, lam = fr.r, fr.z, fr.t, fr.lam
        if fr.flag == "delaminated":
            uu, ww = _skirt(nuis, a, l0)
            r = np.r_[r, (a * lam + uu[1:]) / a]
            z = np.r_[z + ww[0] / a, ww[1:] / a]
            t = np.r_[t, np.ones(uu.size - 1)]
            return (0.0, r, z, t, lam)
        if fr.flag == "fractured" and nuis.fracture_mode == "collapsed":
            length = _flap_length(a, self.h, a * lam)
            return (0.0, r, np.zeros_like(z), t, lam, Collapse(length, _FLAP_ANGLE, float(t[-1]) * l0))
        if fr.flag == "fractured":
            mid = _midline(r, z, a, 0.0)
            s, lo, hi = _torn(mid, fr, nuis)
            w_lo, w_hi = np.interp([lo, hi], s, mid[:, 1])
            if lo < 0.5 < hi:  # (the pole's cap)
                return (0.0, r, z, t, lam, Hole(float(min(w_lo, w_hi)), np.inf, 0))
            side = 1 if lo >= 0.5 else -1
            return (0.0, r, z, t, lam, Hole(float(min(w_lo, w_hi)), float(max(w_lo, w_hi)), side))
        return (0.0, r, z, t, lam)

    def render_optical(self, fr: _Frame, drift, optics, sigma):
        """Bright-field image of the frame from its optics (:func:`optics.render_optical`)."""
        from osmobulge.imaging.optics import render_optical

        chambers = [self._optical_chamber(fr)] + [tuple(nb) for nb in fr.neighbours]
        return render_optical(
            self.shape,
            lambda c, r: self.to_scene(c, r, drift),
            chambers,
            self.a,
            self.h,
            self.l0,
            self.p,
            optics,
            blur_sigma=sigma,
        )


def _field_coords(shape, angle):
    """Each pixel's position from the field's centre (float32, -1 .. 1 at its sides: ``x`` to the right, ``y`` up)
    and along ``angle`` (deg, from ``x`` towards ``y``)."""
    rows, cols = shape
    y, x = np.mgrid[0:rows, 0:cols].astype(np.float32)
    xc, yc = (x - (cols - 1) / 2) / (cols / 2), ((rows - 1) / 2 - y) / (rows / 2)
    th = math.radians(angle)
    return xc, yc, xc * math.cos(th) + yc * math.sin(th)


def _stray(shape, nuis: Nuisances, amount):
    """Additive stray light (float32): ``amount`` at the field's side ``illumination_angle`` points to, none at the
    other, linear between."""
    along = _field_coords(shape, nuis.illumination_angle)[2]
    return (0.5 * amount * (1.0 + along)).astype(np.float32)


def _illumination(shape, nuis: Nuisances, gradient=None):
    """Multiplicative illumination field (float32) or None when uniform (``gradient``: instead of the
    nuisances')."""
    gradient = nuis.illumination_gradient if gradient is None else gradient
    if gradient == 0 and nuis.vignetting == 0:
        return None
    xc, yc, along = _field_coords(shape, nuis.illumination_angle)
    field_ = 1.0 + gradient * along
    field_ *= 1.0 - nuis.vignetting * (xc**2 + yc**2) / 2.0
    return field_.astype(np.float32)


def _dust(shape, nuis: Nuisances, rng, n=None, radius=None):
    """Multiplicative dust transmission (float32) and the specks' parameters (``(x, y, radius, opacity)`` px each;
    ``n`` of them of ``radius``, default the dust's)."""
    rows, cols = shape
    n = nuis.dust_count if n is None else n
    radius = nuis.dust_radius if radius is None else radius
    specks = (
        np.column_stack(
            [
                rng.uniform(0, cols, n),
                rng.uniform(0, rows, n),
                rng.uniform(radius[0], radius[1], n),
                rng.uniform(0.5, 1.0, n) * nuis.dust_opacity,
            ]
        )
        if n
        else np.zeros((0, 4))
    )
    if not n:
        return None, specks
    trans = np.ones(shape, np.float32)
    for xc, yc, rad, op in specks:
        half = int(math.ceil(4 * rad))
        r0, r1 = max(0, int(yc) - half), min(rows, int(yc) + half + 1)
        c0, c1 = max(0, int(xc) - half), min(cols, int(xc) + half + 1)
        if r1 <= r0 or c1 <= c0:
            continue
        yy, xx = np.mgrid[r0:r1, c0:c1]
        trans[r0:r1, c0:c1] *= (1.0 - op * np.exp(-((xx - xc) ** 2 + (yy - yc) ** 2) / (2 * rad * rad))).astype(
            np.float32
        )
    return trans, specks


#: smallest PSF sigma (px) for which domes are drawn as analytically blurred bands
_MIN_ANALYTIC_SIGMA = 0.5
#: photons at full scale above which shot noise uses the normal approximation
_POISSON_NORMAL = 1000.0


def _blur(img, sigma):
    """Gaussian blur (truncated at 4 sigma, edges replicated) of the rows that can change.

    Rows farther than the kernel radius from any row that is not constant, or
    that differs from its neighbour, are left alone: blurring cannot change
    them.  Both passes run along contiguous rows (transposing between them),
    which is several times faster than filtering along columns.
    """
    rad = int(4.0 * sigma + 0.5)
    lo, hi = img.min(axis=1), img.max(axis=1)
    busy = (lo != hi) | (np.r_[lo[1:], lo[-1]] != lo) | (np.r_[lo[0], lo[:-1]] != lo)
    busy = np.convolve(busy.astype(np.int8), np.ones(2 * rad + 3, np.int8), mode="same") > 0
    idx = np.nonzero(busy)[0]
    if idx.size == 0:
        return img
    r0, r1 = max(0, idx[0] - rad - 1), min(img.shape[0], idx[-1] + rad + 2)
    slab = ndimage.gaussian_filter1d(img[r0:r1], sigma, axis=1, mode="nearest", truncate=4.0)
    slab = ndimage.gaussian_filter1d(np.ascontiguousarray(slab.T), sigma, axis=1, mode="nearest", truncate=4.0)
    out = img.copy()
    out[r0:r1] = slab.T
    return out


def _finish(img, nuis: Nuisances, illum, dust, rng, gain=1.0, stray=None):
    """Polarity, dust, illumination (its field and its frame's ``gain``), ``stray`` light (added), noise and
    quantisation of one (blurred) frame."""
    if nuis.polarity < 0:
        img = 1.0 - img
    if dust is not None:
        img *= dust
    if illum is not None:
        img *= illum
    if gain != 1.0:
        img *= np.float32(gain)
    if stray is not None:
        img += stray
    photons, sigma = float(nuis.poisson_photons), float(nuis.noise_sigma)
    if 0 < photons < _POISSON_NORMAL:  # few photons: exact Poisson counts
        img = (rng.poisson(np.clip(img, 0.0, None) * photons) / photons).astype(np.float32)
    var = None
    if photons >= _POISSON_NORMAL:
        # many photons: normal approximation of the shot noise (same mean and variance),
        # drawn together with the read noise in one pass
        var = np.clip(img, 0.0, None) * np.float32(1.0 / photons)
        if sigma > 0:
            var += np.float32(sigma * sigma)
    elif sigma > 0:
        var = np.float32(sigma * sigma)
    if var is not None:
        noise = rng.standard_normal(img.shape, dtype=np.float32)
        noise *= np.sqrt(var)
        img += noise
    full = float(2**nuis.bit_depth - 1)
    dtype = np.uint8 if nuis.bit_depth == 8 else np.uint16
    out = np.rint(np.clip(img, 0.0, 1.0) * np.float32(full))
    return out.astype(dtype)


def _stamp(frame, t, corner, pixel_size, bit_depth):
    """``frame`` (stored orientation) with the time ``t`` (s) burned into ``corner`` ("tl", "tr", "bl" or "br")
    and a 100 um scale bar (``pixel_size`` in m) with its label in the other bottom corner, white (full scale
    of ``bit_depth``), as a microscope's export with annotations (:class:`Nuisances` ``time_stamp``)."""
    from PIL import Image, ImageDraw, ImageFont

    rows, cols = frame.shape
    font = ImageFont.load_default(size=max(10, round(rows / 28)))
    white = 2 ** int(bit_depth) - 1
    im = Image.fromarray(frame.astype(np.int32))  # (mode "I")
    d = ImageDraw.Draw(im)
    t = int(round(t))
    text = f"{t // 3600:02d}:{t % 3600 // 60:02d}:{t % 60:02d}.000  t = {t / 60:.0f} min"
    size = font.size
    x = 10 if corner[1] == "l" else cols - 10 - int(d.textlength(text, font=font))
    d.text((x, 10 if corner[0] == "t" else rows - 10 - 1.3 * size), text, fill=white, font=font)
    bar = int(round(100e-6 / pixel_size))
    x = cols - 10 - bar if corner[1] == "l" else 10
    d.rectangle([x, rows - 10 - size // 4, x + bar, rows - 10], fill=white)
    d.text((x, rows - 14 - size // 4 - 1.3 * size), "100 um", fill=white, font=font)
    return np.asarray(im).astype(frame.dtype)


# --------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------
@dataclass
class SyntheticSeries:
    """A rendered series and its ground truth.

    Attributes
    ----------
    frames : ndarray of shape (T, H, W), uint8 or uint16
        The micrographs.
    truth : xarray.Dataset
        Ground truth over ``time`` (see :func:`render_series`).
    """

    frames: np.ndarray
    truth: xr.Dataset

    def __len__(self):
        return self.frames.shape[0]

    def save(self, folder, fmt="tiff"):
        """Write the frames and ``truth.nc`` into ``folder``.

        Parameters
        ----------
        folder : str or Path
            Created if missing.
        fmt : {"tiff", "ome-tiff", "tiff-folder", "png", "jpeg"}
            "tiff": one multi-page ``frames.tif`` with ImageJ pixel size and
            frame interval; "ome-tiff": ``frames.ome.tif`` with OME-XML
            PhysicalSizeX/Y and per-plane DeltaT; "tiff-folder", "png",
            "jpeg": one file per frame (``frame_00000.ext``) with the
            acquisition time in the file's DateTime metadata.  JPEG holds
            8-bit frames only.

        Returns
        -------
        pathlib.Path
            The frames file (tiff, ome-tiff) or the folder.
        """
        from osmobulge.imaging import io as _io

        path = _io.write_series(
            self.frames,
            folder,
            fmt=fmt,
            pixel_size=float(self.truth.attrs["pixel_size"]),
            timestamps=self.truth["time"].values,
        )
        _io.write_truth(self.truth, folder)
        return path


def _event_flags(n, nuis: Nuisances):
    flags = np.array(["ok"] * n, dtype=object)
    for name, flag in (
        ("delaminated_frames", "delaminated"),
        ("fractured_frames", "fractured"),
        ("touching_frames", "touching"),
    ):
        idx = [i for i in getattr(nuis, name) if i < n]
        if len(idx) != len(getattr(nuis, name)):
            raise ValueError(f"{name} holds frame indices >= the number of frames ({n})")
        flags[idx] = flag
    return flags


def _resample_halves(prof, a, n_s):
    """Half profiles pole->rim resampled uniformly in arc length: r, z, l (T, n_s), arc (T,)."""
    t = prof.r.shape[0]
    s_u = np.linspace(0.0, 1.0, n_s)
    out_r, out_z, out_t = (np.empty((t, n_s)) for _ in range(3))
    arc = np.empty(t)
    for i in range(t):
        seg = np.hypot(np.diff(prof.r[i]), np.diff(prof.z[i]))
        s = np.r_[0.0, np.cumsum(seg)]
        arc[i] = s[-1] * a
        su = s_u * s[-1]
        out_r[i] = np.interp(su, s, prof.r[i]) * a
        out_z[i] = np.interp(su, s, prof.z[i]) * a
        out_t[i] = np.interp(su, s, prof.thickness[i])
    return out_r, out_z, out_t, arc


def _point_segment_distance(pts, seg):
    """Distances (n, m) from points (n, 2) to the m segments of the polyline ``seg`` (m + 1, 2)."""
    a, b = seg[:-1], seg[1:]
    ab = b - a
    len2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    ap = pts[:, None, :] - a[None, :, :]
    u = np.clip(np.einsum("nmk,mk->nm", ap, ab) / len2, 0.0, 1.0)
    closest = a[None, :, :] + u[..., None] * ab[None, :, :]
    return np.hypot(pts[:, None, 0] - closest[..., 0], pts[:, None, 1] - closest[..., 1])


def _polylines_cross(pa, pb):
    """True when any segment of polyline ``pa`` crosses one of ``pb``."""
    def orient(p, q, r):
        cross = (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])
        return np.sign(cross)

    a1, a2 = pa[:-1, None, :], pa[1:, None, :]
    b1, b2 = pb[None, :-1, :], pb[None, 1:, :]
    o1, o2 = orient(a1, a2, b1), orient(a1, a2, b2)
    o3, o4 = orient(b1, b2, a1), orient(b1, b2, a2)
    return bool(np.any((o1 * o2 < 0) & (o3 * o4 < 0)))


def _min_gap(mid_a, thick_a, mid_b, thick_b):
    """Smallest distance between two bands' edges (m); < 0 when they overlap.

    Point-to-segment distances both ways (so subsampled midlines cannot pass between
    each other's samples unnoticed), and -1 when the midlines cross outright.
    """
    if _polylines_cross(mid_a, mid_b):
        return -1.0
    seg_b = 0.5 * (thick_b[:-1] + thick_b[1:])  # band thickness on each segment
    seg_a = 0.5 * (thick_a[:-1] + thick_a[1:])
    d_ab = _point_segment_distance(mid_a, mid_b) - 0.5 * (thick_a[:, None] + seg_b[None, :])
    d_ba = _point_segment_distance(mid_b, mid_a) - 0.5 * (thick_b[:, None] + seg_a[None, :])
    return float(min(d_ab.min(), d_ba.min()))


def render_series(
    vtilde,
    *,
    chamber=REFERENCE_CHAMBER,
    material=PDMS,
    lambda_pre=1.0,
    pixel_size=1.0e-6,
    shape=(1024, 1024),
    times=None,
    scene=None,
    nuisances=None,
    seed=0,
    n_profile=401,
    n_truth=201,
    optics=None,
) -> SyntheticSeries:
    r"""Render a time series of cross-section micrographs of a bulging chamber.

    Parameters
    ----------
    vtilde : array_like of shape (T,)
        Dimensionless bulge volume :math:`\tilde V = \Delta V/(\pi a^3) \geq 0` of
        every frame (main text Eqn 4).
    chamber : tuple of float or Chamber, m
        ``(radius, depth, thickness)`` = :math:`(a, h, l_0)`, or an
        :class:`osmobulge.modeling.transport.Chamber`.  Default: the paper's
        reference chamber (200, 110, 20 um).
    material : Material
        Hyperelastic membrane law (default ``PDMS``).
    lambda_pre : float or callable
        Rim pre-stretch, constant or a function of :math:`\tilde V`
        (e.g. :class:`osmobulge.modeling.PreStretch`).
    pixel_size : float, m
        Square pixel size (default 1 um).
    shape : tuple of int
        Frame shape (rows, columns).
    times : array_like of shape (T,) or None, s
        Acquisition times; default every 600 s from 0.
    scene : SceneGeometry or None
        Layout and grey levels.
    nuisances : Nuisances or None
        Imperfections (default: clean 16-bit render with a 1 px PSF).
    seed : int
        Seed of every random choice (drift, dust, tears, noise); the same seed
        gives the same series.
    n_profile : int
        Reference radii per half profile used to draw the dome.
    n_truth : int
        Arc-length samples of the saved truth profile.
    optics : Optics or None
        Render the bright-field appearance from refractive indices, apertures
        and focus (:mod:`osmobulge.imaging.optics`) instead of painted grey
        levels; ``scene``'s grey levels and ``contrast`` are then unused, the
        other nuisances (blur, polarity, light, noise, bit depth, drift, tilt,
        neighbours, events) apply.  Events are drawn in the scene's
        geometry (:meth:`_Scene._optical_chamber`).

    Returns
    -------
    SyntheticSeries
        ``frames`` (T, H, W) and ``truth``, a Dataset over ``time`` (s) with
        ``vtilde``, ``volume`` (m^3, water added = :math:`\pi a^3 \tilde V`),
        ``volume_ratio`` (:math:`V/V_0 = 1 + \tilde V a/h`), ``bulge_height``
        (m), ``area_ratio`` (:math:`A/A_0`), ``rim_radius`` (m,
        :math:`a\lambda_{pre}`), ``lambda_pre``, ``flag``, ``axis_x`` /
        ``rim_y`` (px: column and row of the point where the chamber axis
        meets the rim line, after tilt and drift), ``tilt`` (deg),
        ``drift_x`` / ``drift_y`` (px), the true half profile ``profile_r``,
        ``profile_z`` (m) and ``profile_thickness`` (m) over ``s`` (arc length
        from the pole, normalised to 1 at the rim), ``profile_arclength``
        (m), and the drawn midline in pixels ``midline_col`` / ``midline_row``
        over (``time``, ``side``, ``s``).  Neighbours add
        ``neighbour_vtilde`` over (``time``, ``neighbour``).

    Notes
    -----
    The truth profile is the model's.  In delaminated frames the drawn dome
    is lifted by ``delamination_gap * l0`` (``midline_row`` includes the lift).
    A frame whose reference dome overlaps a neighbour's band is flagged
    ``touching`` even if it was not listed in ``touching_frames``.
    """
    a, h, l0 = _chamber_tuple(chamber)
    rows, cols = _check_shape(shape)
    p = float(pixel_size)
    if not (math.isfinite(p) and 1e-9 <= p <= 1e-3):
        raise ValueError(f"pixel_size must be in [1e-9, 1e-3] m/px, got {pixel_size!r}")
    v = np.atleast_1d(np.asarray(vtilde, float))
    if v.ndim != 1 or v.size == 0 or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError("vtilde must be a non-empty 1-D array of finite values >= 0")
    n_t = v.size
    if times is None:
        times = np.arange(n_t) * DEFAULT_FRAME_INTERVAL
    times = np.asarray(times, float)
    if times.shape != v.shape or not np.all(np.isfinite(times)):
        raise ValueError(f"times must be finite with the shape of vtilde {v.shape}, got {times.shape}")
    scene = SceneGeometry() if scene is None else scene
    nuis = Nuisances() if nuisances is None else nuisances
    if not isinstance(scene, SceneGeometry):
        raise TypeError(f"scene must be a SceneGeometry, got {type(scene).__name__}")
    if not isinstance(nuis, Nuisances):
        raise TypeError(f"nuisances must be a Nuisances, got {type(nuis).__name__}")
    flags = _event_flags(n_t, nuis)
    if optics is None and nuis.focus_drift != 0.0:
        raise ValueError("focus_drift needs optics: the painted renderer has no focal plane")
    if optics is not None:
        from osmobulge.imaging.optics import Optics

        if not isinstance(optics, Optics):
            raise TypeError(f"optics must be an Optics, got {type(optics).__name__}")

    ss = np.random.SeedSequence(int(seed))
    rng_drift, rng_dust, rng_event = (np.random.default_rng(s) for s in ss.spawn(3))

    # -- drift -----------------------------------------------------------------------
    if nuis.drift is not None:
        drift = np.asarray(nuis.drift, float)
        if drift.shape[0] != n_t:
            raise ValueError(f"drift has {drift.shape[0]} rows for {n_t} frames")
    else:
        steps = rng_drift.normal(0.0, nuis.drift_sigma, (n_t, 2)) if nuis.drift_sigma > 0 else np.zeros((n_t, 2))
        steps[0] = 0.0
        drift = np.cumsum(steps, axis=0)

    # -- profiles: every distinct volume of every chamber in one batched solve --------
    nb = nuis.neighbours
    for off, _ in nb:
        if abs(off) < 2.0 * a * 1.05:
            raise ValueError(f"neighbour offset {off!r} m puts its well onto the reference well (|offset| > 2.1 a)")
    v_nb = [scale * v for _, scale in nb]
    prof = profiles(material, np.concatenate([v, *v_nb]), lambda_pre, n=n_profile)
    ref_slice = slice(0, n_t)

    def rows_of(k):
        return slice((k + 1) * n_t, (k + 2) * n_t)

    nb_v = np.array(v_nb).reshape(len(nb), n_t) if nb else np.zeros((0, n_t))
    nb_prof = [
        (prof.r[rows_of(k)], prof.z[rows_of(k)], prof.thickness[rows_of(k)], prof.lambda_pre[rows_of(k)])
        for k in range(len(nb))
    ]
    nb_prof = [list(map(np.array, x)) for x in nb_prof]

    # touching frames: grow the nearest neighbour until its band overlaps the dome
    if nuis.touching_frames:
        k_near = int(np.argmin([abs(o) for o, _ in nb]))
        off = nb[k_near][0]
        _touch(nuis.touching_frames, prof, k_near, off, nb_v, nb_prof, a, l0, material, lambda_pre, n_profile)

    fracture_centres = rng_event.uniform(0.3, 0.7, n_t)

    # automatic touching flag: the bands overlap; nb_gap, the least gap between the dome's band and a neighbour's
    nb_gap = np.full(n_t, np.inf)
    for i in range(n_t if nb else 0):
        mid = _midline(prof.r[i], prof.z[i], a, 0.0)
        th = l0 * np.r_[prof.thickness[i][::-1], prof.thickness[i][1:]]
        for k, (off, _) in enumerate(nb):
            r_, z_, t_, _lam = (x[i] for x in nb_prof[k])
            gap = _min_gap(mid[::4], th[::4], _midline(r_, z_, a, off)[::4], l0 * np.r_[t_[::-1], t_[1:]][::4])
            nb_gap[i] = min(nb_gap[i], gap)
        if flags[i] == "ok" and nb_gap[i] < 0:
            flags[i] = "touching"

    # -- render ----------------------------------------------------------------------
    sc = _Scene(a, h, l0, p, (rows, cols), scene, nuis)
    c = nuis.contrast
    bg = scene.background_level
    levels = (bg,) + tuple(bg + c * (lv - bg) for lv in (scene.base_level, scene.liquid_level, scene.membrane_level))
    levels = tuple(float(np.clip(x, 0.0, 1.0)) for x in levels)
    illum = _illumination((rows, cols), nuis)
    dust, specks = _dust((rows, cols), nuis, rng_dust)
    dtype = np.uint8 if nuis.bit_depth == 8 else np.uint16
    frames = np.empty((n_t, rows, cols), dtype)
    gains = np.ones(n_t)
    debris = []  # (frame, x, y, radius, opacity) of the particles drifting in the water
    if nuis.exposure_sigma > 0 and n_t > 1:  # (a stream of its own: the other draws as without it)
        rng_exposure = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(8,)))
        gains[1:] = np.clip(1.0 + nuis.exposure_sigma * rng_exposure.standard_normal(n_t - 1), 0.3, 2.0)
    for i in range(n_t):
        fr = _Frame(
            r=prof.r[i],
            z=prof.z[i],
            t=prof.thickness[i],
            lam=float(prof.lambda_pre[i]),
            neighbours=[
                (off, *(x[i] for x in nb_prof[k][:3]), float(nb_prof[k][3][i])) for k, (off, _) in enumerate(nb)
            ],
            flag=str(flags[i]),
            fracture_centre=float(fracture_centres[i]),
        )
        if optics is None:
            img = sc.render(fr, drift[i], levels, nuis.blur_sigma)
        else:
            img = sc.render_optical(fr, drift[i], _frame_optics(optics, nuis, v[i], times, i, a, h), nuis.blur_sigma)
        rng_noise = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(7, i)))
        shade = dust
        if nuis.debris and i > 0:  # (particles drifting in the water: a stream of their own, new places each frame)
            rng_debris = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(9, i)))
            passing, where = _dust((rows, cols), nuis, rng_debris, nuis.debris, nuis.debris_radius)
            shade = passing if dust is None else dust * passing
            debris.append(np.column_stack((np.full(len(where), i), where)))
        frac = (times[i] - times[0]) / (times[-1] - times[0]) if times[-1] != times[0] else 0.0  # (of the series)
        gains[i] *= 1.0 + nuis.exposure_drift * frac  # (the exposure turned up over the series)
        light = illum
        if nuis.light_drift != 0.0 and frac:  # (the light's gradient drifting over the series)
            light = _illumination((rows, cols), nuis, nuis.illumination_gradient + nuis.light_drift * frac)
        stray = _stray((rows, cols), nuis, nuis.stray_light * frac) if nuis.stray_light != 0.0 and frac else None
        frames[i] = _finish(img, nuis, light, shade, rng_noise, float(gains[i]), stray)
        if nuis.time_stamp != "none":
            frames[i] = _stamp(frames[i], times[i] - times[0], nuis.time_stamp, p, nuis.bit_depth)

    truth = _truth(
        v,
        times,
        prof,
        ref_slice,
        flags,
        drift,
        sc,
        a,
        h,
        l0,
        p,
        material,
        lambda_pre,
        nuis,
        scene,
        seed,
        n_truth,
        nb,
        nb_v,
        optics,
    )
    if nb:
        truth["neighbour_gap"] = ("time", nb_gap, {"units": "m", "long_name": "least gap between the dome's band "
                                                  "and a neighbour's (< 0: they overlap, the frame is touching)"})
    if nuis.exposure_sigma > 0 or nuis.exposure_drift != 0:
        truth["light_gain"] = ("time", gains, {"units": "1", "long_name": "the frame's light over the first "
                                                "frame's (the lamp, the exposure)"})
    truth.attrs["dust_specks"] = specks.ravel() if specks.size else "none"
    truth.attrs["debris"] = np.vstack(debris).ravel() if debris else "none"
    if hasattr(chamber, "to_attrs"):  # a modeling Chamber: its loading too (Chamber.from_attrs round-trips)
        truth.attrs.update({k: float(v) for k, v in chamber.to_attrs().items()})
    return SyntheticSeries(frames=frames, truth=truth)


def _frame_optics(optics, nuis: Nuisances, vtilde, times, i, a, h):
    """Frame ``i``'s optics: its focal plane (``nuis.focus_drift``) and, with ``optics.dilution``, its diluted
    salt solution (:class:`~osmobulge.imaging.optics.Optics`)."""
    change = {}
    if nuis.focus_drift != 0.0 and times[-1] != times[0]:
        change["defocus"] = optics.defocus + nuis.focus_drift * (times[i] - times[0]) / (times[-1] - times[0])
    if optics.dilution:
        # (V0/V, the salt's concentration over the first frame's: V = pi a^2 h + pi a^3 Vtilde, main text Eqn 4;
        # a, h in m)
        share = 1.0 / (1.0 + vtilde * a / h)
        change["n_liquid"] = optics.n_water + (optics.n_liquid - optics.n_water) * share
        change["absorption_liquid"] = optics.absorption_liquid * share
    return replace(optics, **change) if change else optics


def _touch(frames_idx, prof, k_near, off, nb_v, nb_prof, a, l0, material, lambda_pre, n_profile):
    """Set the nearest neighbour's volume in touching frames so the bands overlap."""
    from osmobulge.modeling import locking_volume

    lam0 = lambda_pre(0.0) if callable(lambda_pre) else float(lambda_pre)
    vmax = min(locking_volume(material, lam0) * 0.97, 12.0) if math.isfinite(locking_volume(material, lam0)) else 12.0
    grid = np.linspace(0.02, vmax, 64)
    gp = profiles(material, grid, lambda_pre, n=n_profile)
    for i in frames_idx:
        mid = _midline(prof.r[i], prof.z[i], a, 0.0)[::4]
        th = (l0 * np.r_[prof.thickness[i][::-1], prof.thickness[i][1:]])[::4]
        found = None
        for j in range(grid.size):
            m_b = _midline(gp.r[j], gp.z[j], a, off)[::4]
            t_b = (l0 * np.r_[gp.thickness[j][::-1], gp.thickness[j][1:]])[::4]
            if _min_gap(mid, th, m_b, t_b) < -0.5 * min(float(th.min()), float(t_b.min())):
                found = j
                break
        if found is None:
            raise ValueError(
                f"the neighbour at offset {off!r} m cannot reach the reference dome in touching frame {i}; "
                "move it closer (smaller |offset|)"
            )
        nb_v[k_near, i] = grid[found]
        nb_prof[k_near][0][i] = gp.r[found]
        nb_prof[k_near][1][i] = gp.z[found]
        nb_prof[k_near][2][i] = gp.thickness[found]
        nb_prof[k_near][3][i] = gp.lambda_pre[found]


def _truth(
    v, times, prof, sl, flags, drift, sc, a, h, l0, p, material, lambda_pre, nuis, scene, seed, n_truth, nb, nb_v,
    optics=None,
):
    n_t = v.size
    pr, pz, pt, arc = _resample_halves(prof, a, n_truth)
    pr, pz, pt, arc = pr[sl], pz[sl], pt[sl], arc[sl]
    lift = np.where(flags == "delaminated", nuis.delamination_gap * l0, 0.0)
    mid_col = np.empty((n_t, 2, n_truth))
    mid_row = np.empty((n_t, 2, n_truth))
    axis_xy = np.empty((n_t, 2))
    for i in range(n_t):
        for j, sgn in enumerate((-1.0, 1.0)):
            px = sc.to_pixels(np.stack([sgn * pr[i], pz[i] + lift[i]], axis=1), drift[i])
            mid_col[i, j], mid_row[i, j] = px[:, 0], px[:, 1]
        axis_xy[i] = sc.to_pixels(np.array([0.0, 0.0]), drift[i])
    lam = prof.lambda_pre[sl]
    dims = ("time",)

    def var(data, units, long_name, d=dims):
        return (d, data, {"units": units, "long_name": long_name})

    data = {
        "vtilde": var(v, "1", "dimensionless bulge volume dV/(pi a^3)"),
        "volume": var(math.pi * a**3 * v, "m3", "water added: bulge volume over the flat membrane"),
        "volume_ratio": var(1.0 + v * a / h, "1", "chamber volume ratio V/V0 (Eqn 4)"),
        "bulge_height": var(prof.bulge_height[sl] * a, "m", "dome height above the rim plane"),
        "area_ratio": var(prof.area_ratio[sl], "1", "membrane area ratio A/A0"),
        "rim_radius": var(a * lam, "m", "rim radius a lambda_pre"),
        "lambda_pre": var(lam, "1", "rim pre-stretch"),
        "flag": var(flags.astype(str), "1", "frame event: ok|delaminated|fractured|touching"),
        "axis_x": var(axis_xy[:, 0], "px", "column where the chamber axis meets the rim line"),
        "rim_y": var(axis_xy[:, 1], "px", "row where the chamber axis meets the rim line"),
        "tilt": var(np.full(n_t, float(nuis.tilt)), "deg", "device tilt, counter-clockwise as displayed"),
        "drift_x": var(drift[:, 0], "px", "stage drift along columns"),
        "drift_y": var(drift[:, 1], "px", "stage drift along rows"),
        "profile_r": var(pr, "m", "true midline radius r(s)", ("time", "s")),
        "profile_z": var(pz, "m", "true midline height z(s) above the rim plane", ("time", "s")),
        "profile_thickness": var(pt * l0, "m", "membrane thickness l(s)", ("time", "s")),
        "profile_arclength": var(arc, "m", "midline arc length pole to rim"),
        "midline_col": var(mid_col, "px", "drawn midline column, pole to rim", ("time", "side", "s")),
        "midline_row": var(mid_row, "px", "drawn midline row, pole to rim", ("time", "side", "s")),
    }
    if nb:
        data["neighbour_vtilde"] = var(nb_v.T.copy(), "1", "neighbour chambers' vtilde", ("time", "neighbour"))
    coords = {
        "time": ("time", np.asarray(times, float), {"units": "s", "long_name": "time since the first frame"}),
        "s": (
            "s",
            np.linspace(0.0, 1.0, n_truth),
            {"units": "1", "long_name": "arc length from the pole / arc length"},
        ),
        "side": ("side", np.array(["left", "right"]), {"long_name": "half of the profile"}),
        "frame": ("time", np.arange(n_t), {"units": "1", "long_name": "frame index"}),
    }
    if nb:
        coords["neighbour_offset"] = (
            "neighbour",
            np.array([o for o, _ in nb]),
            {"units": "m", "long_name": "neighbour axis offset"},
        )
    dt = float(np.median(np.diff(times))) if n_t > 1 else DEFAULT_FRAME_INTERVAL
    attrs = {
        "title": "synthetic cross-section micrograph series (ground truth)",
        "pixel_size": p,
        "frame_interval": dt,
        "chamber_radius": a,
        "chamber_depth": h,
        "membrane_thickness": l0,
        "material_law": material.law,
        "lambda_pre_law": getattr(lambda_pre, "cache_key", repr(lambda_pre))
        if callable(lambda_pre)
        else float(lambda_pre),
        "seed": int(seed),
        "shape": np.array(sc.shape, np.int64),
        "bit_depth": int(nuis.bit_depth),
        "bulge_direction": scene.bulge_direction,
        "anchor_col": float(sc.anchor[0]),
        "anchor_row": float(sc.anchor[1]),
        "osmobulge_version": __version__,
    }
    for k, val in material.constants.items():
        attrs[f"material_{k}"] = float(val)
    for k, val in asdict(scene).items():
        attrs[f"scene_{k}"] = "auto" if val is None else (np.asarray(val, float) if isinstance(val, tuple) else val)
    attrs.update(nuis.to_attrs())
    if optics is not None:
        attrs.update(optics.to_attrs())
        attrs["appearance"] = "optics"
    else:
        attrs["appearance"] = "painted"
    ds = xr.Dataset(data, coords=coords, attrs=attrs)
    rows, cols = sc.shape
    outside = (mid_col < 0) | (mid_col > cols - 1) | (mid_row < 0) | (mid_row > rows - 1)
    if np.any(outside):
        i = int(np.nonzero(outside.any(axis=(1, 2)))[0][0])
        warnings.warn(
            f"the dome leaves the field from frame {i} on (shape {sc.shape}): enlarge shape or pixel_size",
            UserWarning,
            stacklevel=3,
        )
    return ds


def render_frame(vtilde, **kwargs) -> np.ndarray:
    """Render one frame; same keywords as :func:`render_series`.

    Returns
    -------
    ndarray of shape (H, W)
        Equal to ``render_series([vtilde], **kwargs).frames[0]``.
    """
    return render_series([float(vtilde)], **kwargs).frames[0]


def render_simulation(result, **kwargs) -> SyntheticSeries:
    """Render the series of a simulated actuation (:func:`osmobulge.modeling.simulate`).

    Parameters
    ----------
    result : xarray.Dataset
        Output of ``simulate``: ``time`` (s) and ``vtilde`` (or ``volume_ratio``,
        V/V0, with the chamber given or in the attrs ``chamber_radius``,
        ``chamber_depth``).  The chamber attrs written by ``simulate``
        (``chamber_radius``, ``chamber_depth``, ``membrane_thickness``,
        ``concentration``, ...) become the render's chamber and are copied
        into the truth attrs, so ``Chamber.from_attrs(series.truth.attrs)``
        recovers the chamber.
    **kwargs
        Passed to :func:`render_series` (``material``, ``lambda_pre``,
        ``nuisances``, ...); give the same ``material`` and ``lambda_pre`` as
        the simulation.

    Returns
    -------
    SyntheticSeries

    Examples
    --------
    >>> from osmobulge.modeling import simulate, paper_chamber
    >>> from osmobulge.modeling.materials import PDMS
    >>> sim = simulate(paper_chamber(), PDMS, 2e-12, [0.0, 3600.0, 7200.0])  # doctest: +SKIP
    >>> series = render_simulation(sim, material=PDMS)  # doctest: +SKIP
    """
    if "time" not in result.coords and "time" not in result:
        raise ValueError("result must have a 'time' coordinate (s)")
    times = np.asarray(result["time"].values, float)
    if "vtilde" in result:
        v = np.asarray(result["vtilde"].values, float)
    elif "volume_ratio" in result:
        ch = kwargs.get("chamber")
        if ch is not None:
            a, h, _ = _chamber_tuple(ch)
        elif {"chamber_radius", "chamber_depth"} <= set(result.attrs):
            a, h = float(result.attrs["chamber_radius"]), float(result.attrs["chamber_depth"])
        else:
            raise ValueError("volume_ratio needs the chamber: pass chamber= or set attrs chamber_radius/chamber_depth")
        v = (np.asarray(result["volume_ratio"].values, float) - 1.0) * h / a
    else:
        raise ValueError("result must hold 'vtilde' or 'volume_ratio'")
    if "chamber" not in kwargs and {"chamber_radius", "chamber_depth", "membrane_thickness"} <= set(result.attrs):
        kwargs["chamber"] = tuple(
            float(result.attrs[k]) for k in ("chamber_radius", "chamber_depth", "membrane_thickness")
        )
    out = render_series(np.clip(v, 0.0, None), times=times, **kwargs)
    for k in ("concentration", "feed_concentration", "temperature", "vant_hoff"):
        if k in result.attrs and k not in out.truth.attrs:
            out.truth.attrs[k] = float(result.attrs[k])
    return out
