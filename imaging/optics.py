r"""Bright-field appearance of the device from geometry and refractive indices.

The painted renderer (:mod:`osmobulge.imaging.synthetic` without ``optics``) fills
the membrane with a dark grey.  A real PDMS film in water is not an absorber: it is
seen because it bends light.  This module renders what a transmitted-light
microscope sees of the device viewed from the side, in geometric optics:

1. **Optical path.**  The device is a slab of elastomer of depth ``depth`` along
   the viewing axis ``y`` with its top face at the film's top (``w = l0/2``).  The
   well is a solid of revolution (radius ``a`` at its bottom, ``a lambda_pre`` at
   its top, depth ``h``) filled with salt solution, and the dome is a shell of
   revolution whose mid-surface is the model profile and whose faces lie
   ``+-l/2`` from it along the normal.  A ray parallel to ``y`` at scene position
   ``(u, w)`` crosses each solid of revolution of radius ``R(w)`` along the chord
   ``C = 2 sqrt(R^2 - u^2)``, so the optical path difference against water is

   .. math::

      \mathrm{OPD} = (n_e - n_w)\,[D - C_\mathrm{in}]_{w<l_0/2}
                     + (n_s - n_w)\,C_\mathrm{in}
                     + (n_e - n_w)\,[C_\mathrm{out} - C_\mathrm{in}]_{w \ge l_0/2}

   with ``C_in`` the chord of the liquid (well, or dome interior) and ``C_out``
   the chord of the dome's outer face.  The walls and the dome are therefore
   *silhouettes*: the chord's slope diverges where the ray grazes a face.
2. **Deflection and the objective's acceptance.**  A ray leaves with the
   direction ``theta = grad OPD`` (thin-object limit).  Illumination fills the
   condenser's cone (an annulus ``condenser_inner_na .. condenser_na``); the
   fraction of it whose deflected direction still enters the objective
   (``objective_na``) is the transmitted intensity ``T(|theta|)``, an exact
   overlap of discs in direction space.  Rays bent beyond the aperture are lost:
   faces and walls look dark, and with an annular condenser wider than the
   objective (dark field) only bent light arrives and faces look bright.  The
   thin-object limit holds for the small deflections bright field is judged on
   (a ray bent past the objective's edge is lost, however far); dark field
   collects rays bent by 20-40 degrees near grazing incidence, where it misplaces
   the bright zones by several px (``osmobulge.imaging.looks.OUTSIDE_LOOKS``).
3. **Defocus.**  With the focal plane ``defocus`` (m) from the object, each ray is
   imaged displaced by ``defocus * theta`` (its accepted part), so light bent at a
   face piles up beside it: bright and dark fringes that swap sides through focus.
   The condenser cone blurs the defocused image by ``|defocus| * condenser_na / 2``
   (sigma) and diffraction by ``0.21 wavelength / objective_na``.
4. **Absorption** (optional): Beer-Lambert along the chords, per medium; a dyed
   film gives the "filled absorbing band" look, a slightly turbid base a grey step
   between well and base.
5. **Halo** (optional, phenomenological): the light that partially coherent
   imaging diffracts out of a dark feature into a ring of width ``halo_width``
   around it (``halo_strength`` of the lost light), as phase-contrast-like halos.

The image is computed on an ``oversample``-times finer grid, splatted, blurred and
block-averaged to pixels; flat faces are area-weighted and silhouettes anti-aliased on that
grid (sample-averaged chords, minmod slopes, crossed samples blended by their area inside),
so an edge is where its face is, not at the nearest sub-sample.  Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numba import njit
from scipy import ndimage

__all__ = ["Optics", "Hole", "Collapse", "transmission", "optical_path", "render_optical"]


@dataclass(frozen=True)
class Optics:
    """Optical set-up and media of a bright-field side view (SI units).

    Parameters
    ----------
    n_water, n_elastomer, n_liquid : float
        Refractive indices of the bath, the elastomer (base and film; PDMS
        1.41-1.43) and the salt solution in the well (3 M NaCl ~ 1.36).
    depth : float, m
        Path length of the device slab along the viewing axis.
    objective_na, condenser_na, condenser_inner_na : float
        Objective acceptance and the condenser's illumination annulus
        (``condenser_inner_na = 0``: a full cone).
    defocus : float, m
        Distance of the focal plane from the object (either sign).
    wavelength : float, m
        For the diffraction-limited blur.
    absorption_film, absorption_base, absorption_liquid : float, 1/m
        Beer-Lambert absorption coefficients.
    halo_strength : float
        Fraction (0 .. 1) of the light lost at dark features that reappears in
        a halo around them.
    halo_width : float, m
        Gaussian radius of that halo.
    brightness : float
        Image level of undisturbed light (leaves room for bright fringes).
    oversample : int
        Sub-samples per pixel side.
    dilution : bool
        Read by :func:`osmobulge.imaging.synthetic.render_series`: the salt
        solution is diluted by the water that came in, so ``n_liquid`` and
        ``absorption_liquid`` are the first frame's and a frame whose volume
        is ``V/V0 = 1 + Vtilde a/h`` times the well's (``Vtilde = dV/(pi a^3)``,
        main text Eqn 4; ``V0 = pi a^2 h``) has ``n_water + (n_liquid
        - n_water) V0/V`` and ``absorption_liquid V0/V`` (index and dye linear
        in the concentration; the neighbours take the reference chamber's).
    """

    n_water: float = 1.333
    n_elastomer: float = 1.412
    n_liquid: float = 1.362
    depth: float = 1.0e-3
    objective_na: float = 0.25
    condenser_na: float = 0.10
    condenser_inner_na: float = 0.0
    defocus: float = 0.0
    wavelength: float = 550e-9
    absorption_film: float = 0.0
    absorption_base: float = 0.0
    absorption_liquid: float = 0.0
    halo_strength: float = 0.0
    halo_width: float = 3e-6
    brightness: float = 0.7
    oversample: int = 3
    dilution: bool = False

    def __post_init__(self):
        checks = {
            "n_water": (1.0, 3.0),
            "n_elastomer": (1.0, 3.0),
            "n_liquid": (1.0, 3.0),
            "depth": (1e-6, 1.0),
            "objective_na": (0.01, 1.5),
            "condenser_na": (0.0, 1.5),
            "condenser_inner_na": (0.0, 1.5),
            "defocus": (-1e-3, 1e-3),
            "wavelength": (1e-7, 2e-6),
            "absorption_film": (0.0, 1e7),
            "absorption_base": (0.0, 1e7),
            "absorption_liquid": (0.0, 1e7),
            "halo_strength": (0.0, 1.0),
            "halo_width": (1e-8, 1e-3),
            "brightness": (0.01, 1.0),
        }
        for name, (lo, hi) in checks.items():
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"{name} must be a number in [{lo}, {hi}] (SI units), got {v!r}")
        if self.condenser_inner_na > self.condenser_na:
            raise ValueError("condenser_inner_na must not exceed condenser_na")
        if not (isinstance(self.oversample, int) and 1 <= self.oversample <= 8):
            raise ValueError(f"oversample must be an int in [1, 8], got {self.oversample!r}")
        if not isinstance(self.dilution, bool):
            raise ValueError(f"dilution must be True or False, got {self.dilution!r}")

    def to_attrs(self) -> dict:
        """netCDF-safe attrs (prefixed ``optics_``)."""
        return {f"optics_{f.name}": int(v) if isinstance(v, bool) else v
                for f in fields(self) for v in [getattr(self, f.name)]}


@dataclass(frozen=True)
class Hole:
    """A piece of a dome's shell torn out (a fractured frame): water where its faces and the liquid under them were.

    Over heights ``w_lo .. w_hi`` (m above the flat film's mid-surface) on the side ``side`` of the axis (+1: u > 0,
    -1: u < 0), the wedge of azimuths within ``half_angle`` (rad) of the image plane is water: a ray at ``x`` from
    the axis crosses a circle of radius ``R`` there along ``2 max(0, sqrt(R^2 - x^2) - |x| tan(half_angle))``
    instead of its whole chord, so the silhouette on that side is gone over those heights (a window torn in the
    dome's side seen edge-on; its torn edges are oblique to the rays and make no silhouette of their own).
    ``side = 0``: a hole at the pole, every azimuth above ``w_lo`` (the dome's cap missing).
    """

    w_lo: float
    w_hi: float
    side: int
    half_angle: float = math.pi / 3

    def chords(self, x, w, *chords):
        """The chords (at ``x`` from the axis, heights ``w``) with the wedge taken out; and the mask of samples
        whose silhouettes it removes."""
        band = (w >= self.w_lo) & (w <= self.w_hi)
        if self.side == 0:
            return [np.where(band, 0.0, c) for c in chords], band
        band &= self.side * x > 0.0
        cut = 2.0 * np.abs(x) * math.tan(self.half_angle)
        return [np.where(band, np.clip(c - cut, 0.0, None), c) for c in chords], band


@dataclass(frozen=True)
class Collapse:
    """A dome torn away (a collapsed frame): the film over the well gone, the well open to the bath through the
    film's layer (``|u| < rim``), and its flaps hanging from the rim into the well, drawn as a cone of revolution
    (the torn petals all round, seen from the side): mid-surface from the rim at the film's mid-surface down and
    inwards at ``angle`` (rad below the horizontal) over ``length`` (m), thickness ``thickness`` (m)."""

    length: float
    angle: float
    thickness: float

    def flap_chord(self, x, w, rim, liquid_radius):
        """Path (m) in the flaps, within the liquid (radius ``liquid_radius`` at each point: the flaps' outer face
        leaves the well at its top), of rays at ``x`` from the axis, heights ``w`` (0 outside them)."""
        depth = self.length * math.sin(self.angle)
        mid = rim + w / math.tan(self.angle)  # (w <= 0: the cone narrows downwards)
        half = 0.5 * self.thickness / math.sin(self.angle)  # (its horizontal half width)
        inside = (w <= 0.0) & (w >= -depth)
        outer = np.minimum(mid + half, liquid_radius)
        inner = np.clip(mid - half, 0.0, outer)
        return np.clip(_chord(np.where(inside, outer, 0.0), x) - _chord(np.where(inside, inner, 0.0), x), 0.0, None)


# --------------------------------------------------------------------------------------
# transmission through the apertures
# --------------------------------------------------------------------------------------
def _disc_overlap(d, r1, r2):
    """Area of the intersection of discs of radii r1, r2 whose centres are d apart."""
    d = np.asarray(d, float)
    out = np.zeros_like(d)
    if r1 <= 0 or r2 <= 0:
        return out
    full = d <= abs(r1 - r2)
    out[full] = math.pi * min(r1, r2) ** 2
    part = (~full) & (d < r1 + r2)
    dp = d[part]
    a1 = r1**2 * np.arccos(np.clip((dp**2 + r1**2 - r2**2) / (2 * dp * r1), -1, 1))
    a2 = r2**2 * np.arccos(np.clip((dp**2 + r2**2 - r1**2) / (2 * dp * r2), -1, 1))
    a3 = 0.5 * np.sqrt(np.clip((-dp + r1 + r2) * (dp + r1 - r2) * (dp - r1 + r2) * (dp + r1 + r2), 0, None))
    out[part] = a1 + a2 - a3
    return out


def transmission(theta, optics: Optics) -> np.ndarray:
    """Fraction of the condenser's light, bent by ``theta`` (rad), that the objective accepts.

    The illumination is uniform over the condenser annulus in direction space;
    after bending by ``theta`` it is the same annulus centred on ``theta``, and the
    accepted part is its overlap with the objective's disc.  A point source
    (``condenser_na = 0``) is accepted while ``|theta| <= objective_na``.
    """
    th = np.abs(np.asarray(theta, float))
    o, c, ci = optics.objective_na, optics.condenser_na, optics.condenser_inner_na
    area = math.pi * (c * c - ci * ci)
    if area <= 0:
        return (th <= o).astype(float)
    return (_disc_overlap(th, c, o) - _disc_overlap(th, ci, o)) / area


# --------------------------------------------------------------------------------------
# optical path of the scene
# --------------------------------------------------------------------------------------
def _chord(radius, u, du=None):
    """Chord ``2 sqrt(R^2 - u^2)`` of a circle of radius ``R`` at ``u``; with ``du``, its mean over the sample
    ``u +- du/2`` (exact) within two samples of the silhouette ``|u| = R``, so a silhouette between two
    samples is where it is, not at the nearer one (further out the midpoint value is the mean to 0.3 %)."""
    r = np.broadcast_to(np.asarray(radius, float), np.shape(u))
    out = 2.0 * np.sqrt(np.clip(r * r - u * u, 0.0, None))
    if du is None:
        return out
    near = (np.abs(np.abs(u) - r) < 2.0 * du) & (r > 0)
    rn, un = r[near], u[near]

    def integral(t):  # int_0^t 2 sqrt(R^2 - s^2) ds, t clipped to +-R
        tc = np.clip(t, -rn, rn)
        return tc * np.sqrt(np.clip(rn * rn - tc * tc, 0.0, None)) + rn * rn * np.arcsin(np.clip(tc / rn, -1, 1))

    out[near] = (integral(un + 0.5 * du) - integral(un - 0.5 * du)) / du
    return out


def _faces(r, z, t, a, l0):
    """Inner and outer faces of a half dome (pole -> rim), each as radius(height) samples."""
    mr, mz = a * np.asarray(r, float), a * np.asarray(z, float)
    half = 0.5 * l0 * np.asarray(t, float)
    dr, dz = np.gradient(mr), np.gradient(mz)
    norm = np.hypot(dr, dz)
    norm[norm == 0] = 1.0
    # normal out of the dome: the tangent (pole -> rim) turned by +90 degrees; it points
    # up at the pole, outwards at the equator and down over an overhang
    nr, nz = -dz / norm, dr / norm
    outer = (mr + half * nr, mz + half * nz)
    inner = (mr - half * nr, mz - half * nz)
    return inner, outer


def _radius_of_height(face, w, floor, rim_radius):
    """Radius R(w) of a face of revolution at heights w (0 where the face is absent).

    Heights between ``floor`` and the face's foot take the rim radius (the face
    meets the flat film there); above the face's top the solid is absent.
    """
    fr, fz = face
    order = np.argsort(fz, kind="stable")
    zz, rr = fz[order], fr[order]
    rr = np.maximum(rr, 0.0)
    top = zz[-1]
    out = np.interp(w, zz, rr)
    out = np.where(w < zz[0], rim_radius, out)
    return np.where((w >= floor) & (w <= top), out, 0.0)


def _below(level, w, dw):
    """Fraction of a sample of height ``dw`` centred at ``w`` lying below ``level`` (``w < level`` when dw is None)."""
    if dw is None:
        return (w < level).astype(float)
    return np.clip((level - w) / dw + 0.5, 0.0, 1.0)


def optical_path(u, w, chambers, a, h, l0, optics: Optics, dw=None, cover_out=None):
    """OPD against water (m) and the path lengths in film, base and liquid at scene points.

    Parameters
    ----------
    u, w : ndarray
        Scene coordinates (m): along the rim line, and height above the flat
        membrane's mid-surface.
    chambers : list of (offset, r, z, thickness_ratio, lambda_pre[, event])
        Each chamber's axis offset (m) and half profile (``r, z`` in units of
        ``a``, pole -> rim; a film lifted off the top face beyond the rim
        continues it outwards down to the top face); ``event``, optional: a
        :class:`Hole` in the dome or a :class:`Collapse` of it (``None``: none).
    dw : float, m, optional
        Height of the sample around each point: the flat faces (the device's top
        face, the film's lower face, the well's bottom) are then area-weighted
        over it, so a face between two samples is where it is, not at the
        nearer sample (a face exactly on the grid is otherwise moved by up to
        half a sample); and the chords are averaged over a sample of that
        width near their silhouettes.
    cover_out : list, optional
        With ``dw``: extended by one ``(flat indices, fraction inside, outward
        side +-1)`` per silhouette (each well wall, each dome face) for the
        samples it crosses, for :func:`_blend_silhouettes`.

    Returns
    -------
    opd, path_film, path_base, path_liquid : ndarray
    """
    ne, nw, ns = optics.n_elastomer, optics.n_water, optics.n_liquid
    top = 0.5 * l0
    in_slab = _below(top, w, dw)  # under the top face
    in_base = _below(-top, w, dw)  # under the film
    liquid = np.zeros(np.shape(u))
    shell = np.zeros(np.shape(u))
    cover = []  # (flat indices, fraction inside, side) of the samples a silhouette crosses
    uf, wf = np.ravel(u), np.ravel(w)
    for uc, r, z, t, lam, *event in chambers:
        event = event[0] if event else None
        rim = a * lam
        # the well: radius linear from a (bottom) to a lambda_pre (top face); only its samples are computed
        in_well = np.ravel(in_base - _below(-top - h, w, dw))
        sel = np.flatnonzero(in_well > 0)
        x, ws = uf[sel] - uc, wf[sel]
        rw = a + (rim - a) * (np.clip(ws, -top - h, -top) + top + h) / h
        liquid.flat[sel] += in_well[sel] * _chord(rw, x, dw)
        if dw is not None:
            cover.append(_crossing(sel, rw, x, dw))
        if isinstance(event, Collapse):  # the well open through the film's layer, the flaps hanging into it
            sel = np.flatnonzero((wf >= -top - event.length - (dw or 0.0)) & (wf <= top + (dw or 0.0)))
            x, ws = uf[sel] - uc, wf[sel]
            layer = np.ravel(in_slab - in_base)[sel]
            liquid.flat[sel] += layer * _chord(np.full(x.shape, rim), x, dw)
            wall = np.where(ws < -top, a + (rim - a) * (np.clip(ws, -top - h, -top) + top + h) / h, rim)
            liquid.flat[sel] = np.clip(liquid.flat[sel] - event.flap_chord(x, ws, rim, wall), 0.0, None)
            if dw is not None:
                cover.append(_crossing(sel, np.where(layer > 0, rim, 0.0), x, dw))
            continue
        if np.max(z) * a <= 1e-3 * l0:  # flat membrane: no dome above the top face
            continue
        inner, outer = _faces(r, z, t, a, l0)
        reach = 0.0 if dw is None else dw
        sel = np.flatnonzero((wf >= -top - reach) & (wf <= max(np.max(outer[1]), np.max(inner[1])) + reach))
        x, ws = uf[sel] - uc, wf[sel]
        # the dome's faces: the chords averaged over the sample's width, and over its height at three
        # heights (the top of a face between two samples' rows is then not moved to one of them)
        heights = (ws,) if dw is None else (ws - dw / 3.0, ws, ws + dw / 3.0)
        ci = co = 0.0
        for wk in heights:
            ri = _radius_of_height(inner, wk, -top, rim)
            ro = np.maximum(_radius_of_height(outer, wk, top, rim), ri)
            ci = ci + _chord(ri, x, dw) / len(heights)
            co = co + _chord(ro, x, dw) / len(heights)
            if dw is not None and wk is ws:
                torn = np.zeros(x.shape, bool) if event is None else event.chords(x, ws)[1]
                cover += [_crossing(sel, np.where(torn, 0.0, rad), x, dw) for rad in (ri, ro)]
        if isinstance(event, Hole):
            (ci, co), _ = event.chords(x, ws, ci, co)
        liquid.flat[sel] += (1.0 - np.ravel(in_base)[sel]) * ci
        shell.flat[sel] += (1.0 - np.ravel(in_slab)[sel]) * (co - ci)
    slab = np.clip(optics.depth - liquid, 0.0, None)
    film_path = shell + (in_slab - in_base) * slab
    base_only = in_base * slab
    opd = (ne - nw) * (film_path + base_only) + (ns - nw) * liquid
    if cover_out is not None:
        cover_out.extend(cover)
    return opd, film_path, base_only, liquid


def _crossing(sel, radius, x, du):
    """The samples (flat indices among ``sel``) the silhouette ``|x| = radius`` crosses: their fraction inside
    the chord zone and the side (+-1) the outside lies on."""
    f = np.clip((radius - np.abs(x)) / du + 0.5, 0.0, 1.0) * (radius > 0)
    k = (f > 0) & (f < 1)
    return sel[k], f[k], np.sign(x[k])


def _blend_silhouettes(light, cover, axis=1, sign=1):
    """The samples a silhouette crosses: their inside share takes the first sample inside, the rest the
    first outside (point samples would put the edge at the nearer sample boundary).

    ``axis``, ``sign``: the grid's axis the scene's ``u`` (along the rim line)
    changes most along, and the sign of that change: a silhouette's outside
    (``side`` +-1 in ``u``) is ``side * sign`` samples along it.  An upright
    view's ``u`` grows along the columns (1, +1); a view turned over runs it
    back (1, -1), one turned a quarter along the rows (0, +-1).  Stepping
    along the columns in every view (the code before) took each crossed
    sample's inside and outside the wrong way round in a view turned over:
    its walls' edges moved up to a sample (measured: a flat frame's rim read
    0.30 px small at one phase of the grid, right at others), and in a view
    turned a quarter along the silhouette, not across it.
    """
    out = light.copy()
    n = light.shape[axis]
    for idx, f, side in cover:
        if idx.size == 0:
            continue
        rr, cc = np.unravel_index(idx, light.shape)
        step = (side * sign).astype(int)  # outwards
        if axis == 1:
            c_out, c_in = np.clip(cc + step, 0, n - 1), np.clip(cc - step, 0, n - 1)
            out[rr, cc] = (1.0 - f) * light[rr, c_out] + f * light[rr, c_in]
        else:
            r_out, r_in = np.clip(rr + step, 0, n - 1), np.clip(rr - step, 0, n - 1)
            out[rr, cc] = (1.0 - f) * light[r_out, cc] + f * light[r_in, cc]
    return out


# --------------------------------------------------------------------------------------
# the image
# --------------------------------------------------------------------------------------
def _splat(shape, rows, cols, weight):
    """Bilinear splat of weights at fractional (row, col) positions onto a grid.

    Compiled (:func:`_splat_corners`): numpy's four ``bincount`` passes over the
    oversampled grid took 6.7 s of a 1024 x 1024 frame's 11.5 s.  The same sums
    in the same order, so the same image to the bit (:func:`_splat_numpy`, kept
    for the test).
    """
    shape = (int(shape[0]), int(shape[1]))
    out = _splat_corners(shape[0], shape[1], np.ascontiguousarray(rows, np.float64).ravel(),
                         np.ascontiguousarray(cols, np.float64).ravel(), np.ascontiguousarray(weight).ravel())
    return out.reshape(shape)


@njit(cache=True, nogil=True)
def _splat_corners(n_rows, n_cols, rows, cols, weight):
    """The four corners' bilinear weights added corner by corner, each corner's sum over the samples in their
    order added to the grid after the last's (as ``out += np.bincount(...)`` per corner)."""
    out = np.zeros(n_rows * n_cols)
    part = np.empty(n_rows * n_cols)
    for corner in range(4):
        dr, dc = corner // 2, corner % 2
        part[:] = 0.0
        for i in range(rows.size):
            r0, c0 = np.floor(rows[i]), np.floor(cols[i])
            fr, fc = rows[i] - r0, cols[i] - c0
            rr, cc = int(r0) + dr, int(c0) + dc
            if rr < 0 or rr >= n_rows or cc < 0 or cc >= n_cols:
                continue
            if corner == 0:
                wgt = (1 - fr) * (1 - fc)
            elif corner == 1:
                wgt = (1 - fr) * fc
            elif corner == 2:
                wgt = fr * (1 - fc)
            else:
                wgt = fr * fc
            part[rr * n_cols + cc] += weight[i] * wgt
        out += part
    return out


def _splat_numpy(shape, rows, cols, weight):
    """:func:`_splat` in numpy (the reference its compiled form is tested against)."""
    r0 = np.floor(rows).astype(np.int64)
    c0 = np.floor(cols).astype(np.int64)
    fr, fc = rows - r0, cols - c0
    out = np.zeros(shape[0] * shape[1])
    for dr, dc, wgt in ((0, 0, (1 - fr) * (1 - fc)), (0, 1, (1 - fr) * fc), (1, 0, fr * (1 - fc)), (1, 1, fr * fc)):
        rr, cc = r0 + dr, c0 + dc
        ok = (rr >= 0) & (rr < shape[0]) & (cc >= 0) & (cc < shape[1])
        out += np.bincount((rr[ok] * shape[1] + cc[ok]), weights=(weight * wgt)[ok], minlength=out.size)
    return out.reshape(shape)


def _minmod_gradient(f, q, axis):
    """d f / d (row or col) by the smaller of the one-sided differences (0 where they differ in sign).

    Unlike the central difference it does not reach across a silhouette: the
    sample just outside a wall or a dome's face keeps a zero slope (the central
    difference would darken it by half the first inside sample's chord), and the
    sample the silhouette crosses gets the slope of its own share of the chord.
    """
    f = np.moveaxis(f, axis, 1)
    d = np.diff(f, axis=1) / q
    fwd = np.concatenate([d, d[:, -1:]], axis=1)
    bwd = np.concatenate([d[:, :1], d], axis=1)
    g = np.where(fwd * bwd > 0, np.sign(fwd) * np.minimum(np.abs(fwd), np.abs(bwd)), 0.0)
    return np.moveaxis(g, 1, axis)


def render_optical(shape, to_scene, chambers, a, h, l0, pixel_size, optics: Optics, blur_sigma=0.0):
    """Noise-free bright-field image in [0, 1] (float32) of the scene.

    Parameters
    ----------
    shape : (rows, cols)
    to_scene : callable
        ``(cols, rows) px -> (u, w) m`` for arrays of fractional pixel positions.
    chambers : list of (offset, r, z, thickness_ratio, lambda_pre[, event])
        As :func:`optical_path`.
    a, h, l0 : float, m
    pixel_size : float, m
    optics : Optics
    blur_sigma : float, px
        Extra Gaussian blur (camera, residual aberrations).
    """
    s = optics.oversample
    rows, cols = shape
    sub = (rows * s, cols * s)
    q = pixel_size / s
    rr, cc = np.mgrid[0 : sub[0], 0 : sub[1]].astype(float)
    pr = (rr + 0.5) / s - 0.5  # sub-sample centres in pixel coordinates
    pc = (cc + 0.5) / s - 0.5
    u, w = to_scene(pc, pr)
    cover = []
    opd, p_film, p_base, p_liq = optical_path(u, w, chambers, a, h, l0, optics, dw=q, cover_out=cover)
    # the slopes: along the rim line (u) without reaching over a silhouette (walls, the dome's sides); across it
    # (w) the same above the top face (the dome's top), central at and below it, where the flat faces' lines are
    # the steps of their area-weighted paths (a one-sided smaller slope of a step is 0: the faces vanished when
    # the dome grew left or right, w along the columns, until the image axis was taken from w's own direction)
    ax_w = 0 if abs(w[-1, 0] - w[0, 0]) * sub[1] >= abs(w[0, -1] - w[0, 0]) * sub[0] else 1
    g_w = np.where(w > 0.5 * l0 + 1.5 * q, _minmod_gradient(opd, q, ax_w), np.gradient(opd, q, axis=ax_w))
    g_u = _minmod_gradient(opd, q, 1 - ax_w)
    g_row, g_col = (g_w, g_u) if ax_w == 0 else (g_u, g_w)
    theta = np.hypot(g_row, g_col)
    du = (u[1, 0] - u[0, 0], u[0, 1] - u[0, 0])  # (u's change a sample down the rows, along the columns)
    ax_u = 1 if abs(du[1]) >= abs(du[0]) else 0
    light = _blend_silhouettes(transmission(theta, optics), cover, ax_u, 1 if du[ax_u] > 0 else -1)
    absorb = optics.absorption_film * p_film + optics.absorption_base * p_base + optics.absorption_liquid * p_liq
    if np.any(absorb):
        light = light * np.exp(-absorb)
    if optics.defocus != 0.0:
        # the accepted part of a bent bundle travels on at (at most) the aperture's angle
        scale = np.minimum(theta, optics.objective_na) / np.maximum(theta, 1e-300)
        shift = optics.defocus / q * scale
        img = _splat(sub, rr + shift * g_row, cc + shift * g_col, light)
    else:
        img = light
    sig = math.hypot(0.21 * optics.wavelength / optics.objective_na, 0.5 * abs(optics.defocus) * optics.condenser_na)
    sig_sub = math.hypot(sig / q, blur_sigma * s)
    if optics.halo_strength > 0:
        # reference level: what an undisturbed region transmits
        ref = float(transmission(0.0, optics))
        lost = np.clip(ref - img, 0.0, None)
        img = img + optics.halo_strength * ndimage.gaussian_filter(lost, optics.halo_width / q, mode="nearest")
    img = ndimage.gaussian_filter(img, sig_sub, mode="nearest")
    img = img.reshape(rows, s, cols, s).mean(axis=(1, 3))
    norm = float(transmission(0.0, optics))
    if norm < 0.05:  # dark field: scale by what a face at the aperture's edge sends
        norm = float(np.max(transmission(np.linspace(0, 2, 401), optics)))
    return np.clip(img * (optics.brightness / norm), 0.0, 1.0).astype(np.float32)
