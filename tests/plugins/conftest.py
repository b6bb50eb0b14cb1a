"""A small synthetic experiment folder for the plugin tests (rendered once per session)."""

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))  # the tests import plugin_helpers (--import-mode=importlib)

from plugin_helpers import BAD, CHAMBER, INTERVAL_MIN, PIXEL, SHAPE, TOML, VTILDE  # noqa: E402


@pytest.fixture(scope="session")
def rendered_experiment(tmp_path_factory):
    """Write the experiment once: frames/*.tif, experiment.toml, truth.nc."""
    import tifffile

    from osmobulge.imaging.synthetic import Nuisances, render_series

    folder = tmp_path_factory.mktemp("rendered") / "experiment"
    series = render_series(
        list(VTILDE), chamber=CHAMBER, pixel_size=PIXEL, shape=SHAPE, seed=3,
        times=np.arange(len(VTILDE)) * INTERVAL_MIN * 60.0,
        nuisances=Nuisances(noise_sigma=0.01, fractured_frames=(BAD,)),
    )
    (folder / "frames").mkdir(parents=True)
    for i, frame in enumerate(series.frames):
        tifffile.imwrite(folder / "frames" / f"frame_{i:03d}.tif", frame)
    a, h, l0 = (v * 1e6 for v in CHAMBER)
    (folder / "experiment.toml").write_text(TOML.format(a=a, h=h, l0=l0, p=PIXEL * 1e6, dt=INTERVAL_MIN))
    series.truth.to_netcdf(folder / "truth.nc", engine="h5netcdf")
    return folder, series.truth


@pytest.fixture
def experiment(rendered_experiment, tmp_path):
    """A fresh copy of the experiment folder for one test, and its truth."""
    src, truth = rendered_experiment
    dst = tmp_path / "experiment"
    shutil.copytree(src, dst)
    return dst, truth
