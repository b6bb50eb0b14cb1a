"""Compile the image tracers' numba kernels into numba's disk cache, once.

``.ci/run`` runs this while the test extras install: every pytest-xdist worker
would otherwise compile them itself (measured on CI's kind of machine: the band
route's about 110 s in a fresh process, the silhouette route's about 25 s more).
Nothing to do when they are on disk already.
"""

from osmobulge.imaging._kernels import compiled_on_disk

if not compiled_on_disk():
    from osmobulge.imaging._facetrace import SilhouetteTracer
    from osmobulge.imaging.looks import render_look
    from osmobulge.imaging.synthetic import render_series
    from osmobulge.imaging.trace import trace_series
    from osmobulge.modeling.transport import Chamber

    s = render_series([0.0, 0.3, 2.0], chamber=Chamber(100e-6, 50e-6, 10e-6, 3000.0), shape=(420, 440),
                      pixel_size=1e-6, seed=1)
    trace_series(s.frames)
    s = render_look("edge_dark", [0.0, 0.6], shape=(700, 900))
    tracer = SilhouetteTracer(s.frames[0], l0_px=25.0, depth_px=137.5)
    for i, frame in enumerate(s.frames):
        tracer.process(frame, i)
