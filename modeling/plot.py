"""Matplotlib figures of the mechanics (no file I/O: callers save the figure)."""

from __future__ import annotations

import numpy as np

__all__ = ["plot_mechanics"]


def plot_mechanics(datasets, *, labels=None, thickness_over_radius=0.1):
    r"""Plot :math:`f_A`, :math:`f_l` and :math:`f_p` against :math:`\tilde V`.

    Parameters
    ----------
    datasets : xarray.Dataset or sequence of them
        Outputs of :func:`~osmobulge.modeling.bulge_mechanics` (or
        ``MechanicsTable.to_dataset()``).
    labels : sequence of str, optional
        Legend labels, one per dataset.
    thickness_over_radius : float
        :math:`l_0/a` used to convert the pressure to :math:`f_p = P_t/E`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    if not isinstance(datasets, list | tuple):
        datasets = [datasets]
    labels = labels or [ds.attrs.get("material_law", f"#{i}") for i, ds in enumerate(datasets)]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), constrained_layout=True)
    for ds, label in zip(datasets, labels, strict=True):
        v = ds["vtilde"].values
        scale = ds.attrs.get("stress_scale_Pa", np.nan) / ds.attrs.get("nondimensionalising_modulus_Pa", np.nan)
        axes[0].plot(v, ds["area_ratio"], label=label)
        axes[1].plot(v, ds["inverse_thickness"], label=label)
        axes[2].plot(v, ds["pressure"] * scale * thickness_over_radius, label=label)
    for ax, name in zip(axes, ["$f_A = A/A_0$", r"$f_l = \langle l_0/l\rangle$", "$f_p = P_t/E$"], strict=True):
        ax.set_xlabel(r"$\tilde V$")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
    axes[0].legend()
    axes[2].set_title(f"$l_0/a$ = {thickness_over_radius:g}", fontsize=9)
    return fig
