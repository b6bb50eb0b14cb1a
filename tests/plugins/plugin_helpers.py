"""Constants and helpers of the plugin tests' synthetic experiment (imported by conftest and the tests)."""

import numpy as np

#: chamber (radius, depth, membrane thickness), m; pixel size, m; frame shape
CHAMBER = (100e-6, 60e-6, 10e-6)
PIXEL = 2e-6
SHAPE = (200, 240)
VTILDE = (0.0, 0.3, 0.6, 0.9, 1.2, 1.5)
#: the deliberately bad frame: rendered fractured (a gap in the dome's membrane)
BAD = 3
INTERVAL_MIN = 10.0

TOML = """\
[experiment]
name = "plugin-test"
condition = "reference"
material = "PDMS"
date = 2024-01-01
operator = "pytest"

[chamber]
radius_um = {a:g}
depth_um = {h:g}
membrane_thickness_um = {l0:g}
concentration_M = 3.0

[imaging]
frames = "frames"
pixel_size_um = {p:g}
frame_interval_min = {dt:g}
bulge_direction = "up"
"""


def truth_midline_rc(truth, frame):
    """The rendered membrane midline of a frame, rim to rim, ``(row, col)`` px."""
    t = truth.isel(time=frame)
    col = np.concatenate([t.midline_col.sel(side="left").values[::-1], t.midline_col.sel(side="right").values[1:]])
    row = np.concatenate([t.midline_row.sel(side="left").values[::-1], t.midline_row.sel(side="right").values[1:]])
    return np.c_[row, col]
