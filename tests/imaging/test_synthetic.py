"""Tests of the synthetic micrograph renderer (osmobulge.imaging.synthetic)."""

import numpy as np
import pytest
from osmobulge.imaging.synthetic import Nuisances, render_series

SMALL = dict(chamber=(100e-6, 50e-6, 10e-6), shape=(400, 420))


def test_deterministic_under_seed():
    nu = Nuisances(noise_sigma=0.02, drift_sigma=2.0, dust_count=5)
    a = render_series([0.5, 1.0, 2.0], seed=3, nuisances=nu, **SMALL)
    b = render_series([0.5, 1.0, 2.0], seed=3, nuisances=nu, **SMALL)
    c = render_series([0.5, 1.0, 2.0], seed=4, nuisances=nu, **SMALL)
    np.testing.assert_array_equal(a.frames, b.frames)
    np.testing.assert_array_equal(a.truth.drift_x.values, b.truth.drift_x.values)
    assert np.any(a.frames != c.frames)
    assert not np.allclose(a.truth.drift_x.values[1:], c.truth.drift_x.values[1:])
