"""Benchmark: the tracer on optics-rendered looks (issue 16), one row per look.

Run with ``python benchmarks/looks.py [--frames 9] [--held-out-only]``.

Each look (:mod:`osmobulge.imaging.looks`) renders the reference chamber
(0.8 um/px unless the look says otherwise, 1024 x 1024, rim pre-stretch
1 + 0.01 Vtilde) over Vtilde = 0 -> 4 with the flat frame first, and
:func:`osmobulge.imaging.extract.extract` measures it.  Columns: worst volume
error / tolerance over frames flagged ok (tolerance max(3 %, 0.5 px layer over
the rim disc)), the fraction of frames within it, the median rim-radius bias
(px), the worst lambda_pre error, frames flagged, the frames the truth marks as
events (the domes touching a neighbour's) flagged / all such frames, and silent
errors (frames flagged ok but outside the volume or 0.5 px rim tolerance).  The
fraction within tolerance ("V ok") leaves the event frames out.  The second column is
the route ``extract`` took (``tracer="auto"``: band or silhouette), the last two
the render and extraction times per frame.  ``HELD_OUT_LOOKS`` are printed
apart: they are measured, never tuned on; ``OUTSIDE_LOOKS`` (dark field) last, where
the row is the refusal.  A look where the chamber is not found
prints the error instead.

``--events gap|polar|collapsed`` renders each look with events drawn by the
optics model as well: the film delaminated in frame ``n // 3`` and torn in
frames ``n // 2`` and ``n - 2`` (``gap``: a piece of ``fracture_gap`` 0.15 of the
arc, on a side or over the pole as the seed falls; ``polar``: 0.4, always the
cap; ``collapsed``: the dome torn away); the "events flagged" column then counts
them, and a frame after an event must be read again.  ``--stamp tl|tr|bl|br``
burns a time stamp into that corner of every frame (and a scale bar into a
bottom one), as a microscope's export with annotations does.  ``--focus-drift UM``
moves the focal plane by that much from the first frame to the last (the painted
looks have none: unchanged), and ``--dilution`` dilutes the salt solution by the
water that came in (``Optics.dilution``).  ``--jpeg Q`` reads every frame as an
8-bit JPEG at quality Q (a video or a small export).  ``--debris N`` draws N
particles drifting in the water in every frame after the first, each at a new
place (``Nuisances.debris``).  ``--start V0`` starts the series at Vtilde V0
(the same spacing, scaled): a first frame that is not flat.  ``--light-drift D``
changes the light's gradient across the field by D from the first frame to the
last (``Nuisances.light_drift``: +-D at the field's sides by the last frame), and
``--stray-light S`` adds stray light growing to S of full scale on one side by
the last frame (``Nuisances.stray_light``), and ``--exposure-drift D`` turns the
exposure up to 1 + D by the last frame (``Nuisances.exposure_drift``; the light
over the full scale clips).

``--stage-jumps A`` moves every frame after the first by a random (rows, columns)
within +-A px (interpolated; the rows and columns a move brings in repeat the
edge's), as a multi-position series revisiting its positions or a bumped stage.
``--drawn N [--batch B]`` measures N looks drawn at random from plausible
ranges (:func:`osmobulge.imaging.looks.drawn_look`; the batch defaults to
today's date, so a new day's batch is new held-out looks nobody has tuned on;
the batches measured are kept in ``DRAWN_BATCHES``) instead of the named ones.
The options above that set a nuisance override a look's own only when given: a drawn look keeps its drawn
stamp, focus drift, particles and light changes (until 2026-12-08 their defaults zeroed them).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from osmobulge.imaging.extract import extract
from osmobulge.imaging.looks import HELD_OUT_LOOKS, LOOKS, OUTSIDE_LOOKS, get_look, render_look, score
from osmobulge.modeling import PreStretch
from osmobulge.modeling.transport import Chamber

PRE = PreStretch(0.01, 0.0)


def _as_jpeg(frames, quality):
    """The frames as 8-bit JPEG files at ``quality`` would give them back (scaled to their greatest value)."""
    import io

    from PIL import Image

    top = float(np.max(frames))
    out = []
    for f in np.asarray(frames, float):
        buf = io.BytesIO()
        Image.fromarray(np.rint(f / top * 255.0).astype(np.uint8)).save(buf, "JPEG", quality=quality)
        out.append(np.asarray(Image.open(io.BytesIO(buf.getvalue()))))
    return np.stack(out)


def _nuisances(name, n, events=None, stamp=None, focus_drift=None, debris=None, light_drift=None, stray_light=None,
               exposure_drift=None):
    """The look's nuisances with the events of ``--events`` in a series of n frames and those of the options given
    (not None): the ``--stamp``, the ``--focus-drift`` (m; none for a painted look), the ``--debris``, the
    ``--light-drift``, the ``--stray-light`` and the ``--exposure-drift``.  An option not given keeps the look's
    own (a drawn look's light changes, particles, focus drift and stamp)."""
    look = get_look(name)
    torn = {} if events is None else {"delaminated_frames": (n // 3,), "fractured_frames": (n // 2, n - 2), **{
        "gap": {"fracture_gap": 0.15}, "polar": {"fracture_gap": 0.4},
        "collapsed": {"fracture_mode": "collapsed"}}[events]}
    if look.optics is None and focus_drift is not None:
        focus_drift = 0.0
    given = {"time_stamp": stamp, "focus_drift": focus_drift, "debris": debris, "light_drift": light_drift,
             "stray_light": stray_light, "exposure_drift": exposure_drift}
    return replace(look.nuisances, **{k: v for k, v in given.items() if v is not None}, **torn)


def _jumped(frames, amplitude, seed=5):
    """Every frame after the first moved by a random (rows, columns) within +-amplitude px (linear interpolation,
    the edges' rows and columns repeated into the field)."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    shifts = np.vstack([[0.0, 0.0], rng.uniform(-amplitude, amplitude, (len(frames) - 1, 2))])
    return np.stack([np.rint(ndimage.shift(np.asarray(f, float), d, order=1, mode="nearest")).astype(f.dtype)
                     for f, d in zip(frames, shifts, strict=True)])


def row(name, vt, events=None, stamp=None, focus_drift=None, dilution=False, jpeg=None, debris=None,
        light_drift=None, stray_light=None, exposure_drift=None, stage_jumps=0.0):
    t0 = time.perf_counter()
    optics = get_look(name).optics
    if optics is not None and dilution:
        optics = replace(optics, dilution=True)
    s = render_look(name, vt, lambda_pre=PRE,
                    nuisances=_nuisances(name, len(vt), events, stamp, focus_drift, debris, light_drift,
                                         stray_light, exposure_drift),
                    optics=optics)
    t_render = time.perf_counter() - t0
    a, h, l0 = (s.truth.attrs[k] for k in ("chamber_radius", "chamber_depth", "membrane_thickness"))
    frames = s.frames if not stage_jumps else _jumped(s.frames, stage_jumps)
    frames = frames if jpeg is None else _as_jpeg(frames, jpeg)
    t0 = time.perf_counter()
    try:
        ds = extract(frames, pixel_size=s.truth.attrs["pixel_size"], chamber=Chamber(a, h, l0, 3000.0),
                     progress=False, frame_interval=600.0)
    except Exception as exc:  # noqa: BLE001 - the benchmark reports every failure as a row
        return f"| {name:20s} | {type(exc).__name__}: {str(exc)[:90]} |"
    t_extract = time.perf_counter() - t0
    sc = score(s.truth, ds)
    worst_rim = float(np.nanmax(np.abs(sc["rim_bias_px"])))
    return (f"| {name:20s} | {ds.attrs['tracer']:10s} | {sc['worst_dv_tol']:8.2f} |"
            f" {100 * sc['frac_volume_ok']:5.0f} % |"
            f" {sc['median_rim_bias_px']:+6.2f} | {worst_rim:5.2f} | {100 * sc['worst_lambda_err']:6.2f} % |"
            f" {sc['n_flagged']:2d}/{len(vt):<2d} | {sc['n_events_flagged']}/{sc['n_events']} |"
            f" {sc['n_silent']:2d} | {t_render / len(vt):5.1f} s |"
            f" {t_extract / len(vt):5.2f} s |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=9, help="frames from Vtilde 0 to 4")
    ap.add_argument("--held-out-only", action="store_true")
    ap.add_argument("--events", choices=("gap", "polar", "collapsed"),
                    help="draw a delaminated and two torn frames in each look (see the module's docstring)")
    ap.add_argument("--stamp", choices=("none", "tl", "tr", "bl", "br"),
                    help="burn a time stamp into that corner of every frame and a scale bar into a bottom one "
                         "(each option not given keeps the look's own: a drawn look's)")
    ap.add_argument("--focus-drift", type=float, metavar="UM",
                    help="the focal plane's travel (um) from the first frame to the last (optics looks)")
    ap.add_argument("--dilution", action="store_true",
                    help="the salt solution diluted by the water that came in (optics looks)")
    ap.add_argument("--jpeg", type=int, metavar="Q", help="read the frames as 8-bit JPEGs at quality Q (1-95)")
    ap.add_argument("--debris", type=int, metavar="N",
                    help="N particles drifting in the water in every frame after the first")
    ap.add_argument("--start", type=float, default=0.0, metavar="V0",
                    help="the first frame's Vtilde (a series that starts bulged)")
    ap.add_argument("--light-drift", type=float, metavar="D",
                    help="the light's gradient across the field changes by D from the first frame to the last")
    ap.add_argument("--stray-light", type=float, metavar="S",
                    help="stray light growing to S of full scale on one side by the last frame")
    ap.add_argument("--exposure-drift", type=float, metavar="D",
                    help="the exposure turned up to 1 + D by the last frame (light over the full scale clips)")
    ap.add_argument("--stage-jumps", type=float, default=0.0, metavar="A",
                    help="move every frame after the first by a random (rows, columns) within +-A px")
    ap.add_argument("--drawn", type=int, default=0, metavar="N",
                    help="measure N looks drawn at random (imaging.looks.drawn_look) instead of the named ones")
    ap.add_argument("--batch", type=int, default=int(time.strftime("%Y%m%d")), metavar="B",
                    help="the drawn looks' batch (default today's date: new looks)")
    args = ap.parse_args()
    vt = np.linspace(0.0, 4.0, args.frames) ** 1.5 / 2.0
    if args.start:
        vt = args.start + (4.0 - args.start) * vt / 4.0
    head = ("| look                 | route | worst dV/tol (ok) | V ok | rim bias px (median) | worst rim px |"
            " worst dlambda | flagged | events flagged | silent | render/frame | extract/frame |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|")
    groups = [("held-out looks (never tuned on)", HELD_OUT_LOOKS)]
    if args.drawn:
        groups = [(f"looks drawn at random, batch {args.batch}",
                   [f"drawn_{args.batch}_{k}" for k in range(args.drawn)])]
    elif not args.held_out_only:
        groups.insert(0, ("presets", LOOKS))
        groups.append(("outside the method (must be refused with a reason)", OUTSIDE_LOOKS))
    for title, looks in groups:
        events = "" if args.events is None else f" (events: {args.events})"
        events += "" if args.stamp is None else f" (time stamp: {args.stamp})"
        events += "" if args.focus_drift is None else f" (focus drift: {args.focus_drift:+g} um)"
        events += " (liquid diluted)" if args.dilution else ""
        events += "" if args.jpeg is None else f" (JPEG, quality {args.jpeg})"
        events += "" if args.debris is None else f" (debris: {args.debris} a frame)"
        events += "" if not args.start else f" (first frame at Vtilde {args.start:g})"
        events += "" if args.light_drift is None else f" (light's gradient drifting by {args.light_drift:g})"
        events += "" if args.stray_light is None else f" (stray light to {args.stray_light:g} of full scale)"
        events += "" if args.exposure_drift is None else f" (exposure to {1 + args.exposure_drift:g}x)"
        events += "" if not args.stage_jumps else f" (stage jumps within +-{args.stage_jumps:g} px)"
        print(f"\n## {title}{events}: Vtilde {', '.join(f'{x:.2f}' for x in vt)}\n")
        print(head)
        for name in looks:
            focus = None if args.focus_drift is None else args.focus_drift * 1e-6
            print(row(name, vt, args.events, args.stamp, focus, args.dilution, args.jpeg,
                      args.debris, args.light_drift, args.stray_light, args.exposure_drift, args.stage_jumps),
                  flush=True)


if __name__ == "__main__":
    main()
