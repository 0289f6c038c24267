"""Figures of aggregation jobs, after Degond, Dimarco, Ferreira & Hecht (2024)."""

from dataclasses import replace

import numpy as np
import xarray as xr
from matplotlib.collections import EllipseCollection
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from parsim.comparison import method_comparison
from parsim.plots.common import (REALIZATION, axis_label, curves, draw_curve, ensemble, ensemble_figure, figure,
                                 legend, new_figure, panels, position_label, read_snapshot, task_text,
                                 titled)
from parsim.plots.render import distinct_colours, render_spheres
from parsim.solver import flag_value, named_values

FIGURES: dict = {}
N_LABEL = "number of spheres $N$"
COMPARED = ("fractal_dimension", "contact_number", "pair_distribution", "aspect_ratio", "orientation")
"""The variables :func:`parsim.comparison.method_comparison` reads."""
COMPARED_DIMS = {"method", "n_spheres", "volume_fraction", REALIZATION}
DODGE = 1.04  # factor between the N of neighbouring point clouds on the log axis of the orientation figure


def power_law(x: np.ndarray, y: np.ndarray) -> tuple[float, float] | None:
    """(exponent, prefactor) of the least-squares line through (log x, log y); None below two points."""
    usable = np.isfinite(y) & (y > 0) & (x > 0)
    if len(np.unique(x[usable])) < 2:
        return None
    exponent, intercept = np.polyfit(np.log(x[usable]), np.log(y[usable]), 1)
    return float(exponent), float(np.exp(intercept))


@figure(FIGURES, "wall_time", variables=("wall_time",), dims=("n_spheres",))
def wall_time(dataset: xr.Dataset) -> Figure:
    """Wall-clock time of a task against N in log-log scale, with the fitted exponent (Degond et al. 2024, Fig. 6).

    One panel per time-step factor if it is swept.  As in the paper, the exponent is the
    least-squares slope of log(mean time) against log N; the fitted line is dotted.
    """
    variable = dataset.wall_time
    n = variable["n_spheres"].values.astype(np.float64)
    fig, pairs = panels(variable, "time_step_factor")
    for ax, part in pairs:
        for curve in curves(part, keep=("n_spheres",)):
            mean, spread = ensemble(part.isel(curve.selection))
            fit = power_law(n, mean.values)
            if fit is not None:
                curve = replace(curve, label=f"{curve.label + ': ' if curve.label else ''}exponent {fit[0]:.3f}")
                ax.plot(n, fit[1] * n ** fit[0], color=curve.style["color"], linestyle=":", linewidth=1)
            draw_curve(ax, n, mean.values, spread.values, curve)
        ax.set(xscale="log", yscale="log", xlabel=axis_label(variable["n_spheres"], N_LABEL),
               ylabel=axis_label(variable, "wall time per task"))
        legend(ax)
    return titled(fig, dataset, "computational effort")


@figure(FIGURES, "contact_number", variables=("contact_number",), dims=("n_spheres",))
def contact_number(dataset: xr.Dataset) -> Figure:
    """Relative average number of contacts per sphere N_c against N (Degond et al. 2024, Fig. 7)."""
    fig = ensemble_figure(dataset.contact_number, "n_spheres", xscale="log", xlabel=N_LABEL,
                          ylabel="relative number of contacts $N_c$")
    return titled(fig, dataset, "contacts per sphere")


@figure(FIGURES, "pair_distribution", variables=("pair_distribution",))
def pair_distribution(dataset: xr.Dataset) -> Figure:
    """Pair distribution P(r) against r / R, one panel per N (Degond et al. 2024, Figs. 8 and 15).

    Ensemble mean with a band of one standard deviation.
    """
    fig = ensemble_figure(dataset.pair_distribution, "r", panel="n_spheres", band=True, xlabel="$r / R$",
                          ylabel="$P(r)$")
    return titled(fig, dataset, "pair distribution")


@figure(FIGURES, "box_counting", variables=("box_count",))
def box_counting(dataset: xr.Dataset) -> Figure:
    """Boxes holding a sphere centre, 𝒩(ε), against the box side ε / L in log-log scale, one panel
    per N (Degond et al. 2024, Figs. 10, 16, 17)."""
    fig = ensemble_figure(dataset.box_count, "box_size", panel="n_spheres", xscale="log", yscale="log",
                          xlabel=r"box side $\varepsilon / L$", ylabel=r"$\mathcal{N}(\varepsilon)$")
    return titled(fig, dataset, "box counting")


@figure(FIGURES, "fractal_dimension", variables=("fractal_dimension",), dims=("n_spheres",))
def fractal_dimension(dataset: xr.Dataset) -> Figure:
    """Box-counting fractal dimension D_f against N (Degond et al. 2024, Fig. 11 left)."""
    fig = ensemble_figure(dataset.fractal_dimension, "n_spheres", xscale="log", xlabel=N_LABEL,
                          ylabel="fractal dimension $D_f$")
    return titled(fig, dataset, "fractal dimension")


def _both_methods(dataset: xr.Dataset) -> list[str]:
    """What :func:`method_comparison` needs beyond its variables."""
    needs = []
    if "method" not in dataset.dims or not {"ed", "ts"} <= set(named_values(dataset["method"])):
        needs.append("a dimension 'method' holding 'ed' and 'ts' (sweep method = [\"ed\", \"ts\"])")
    needs += [f"coordinate {name!r}" for name in ("n_spheres", "volume_fraction") if name not in dataset.coords]
    other = set(dataset.fractal_dimension.dims) - COMPARED_DIMS
    if other:
        needs.append("a sweep over method, n_spheres and volume_fraction only "
                     f"(it also sweeps {', '.join(sorted(other))})")
    return needs


@figure(FIGURES, "fractal_error", variables=COMPARED, check=_both_methods)
def fractal_error(dataset: xr.Dataset) -> Figure:
    """Relative error |D_f,TS - D_f,ED| / D_f,ED of the mean fractal dimensions against N, per
    volume fraction (Degond et al. 2024, Fig. 11 right), from :func:`parsim.comparison.method_comparison`."""
    rows = method_comparison(dataset)
    fig, (ax,) = new_figure(1)
    fractions = sorted({row["volume_fraction"] for row in rows})
    for k, fraction in enumerate(fractions):
        points = sorted((row["n_spheres"], row["e(D_f)"]) for row in rows if row["volume_fraction"] == fraction)
        n, error = np.array(points).T
        ax.plot(n, 100 * error, marker="o", color=f"C{k % 10}", label=f"volume_fraction = {fraction:g}")
    errors = np.array([row["e(D_f)"] for row in rows])
    ax.set(xscale="log", xlabel=N_LABEL, ylabel="relative error of $D_f$, TS against ED [%]")
    ax.set_title(f"largest {errors.max():.1%}, mean {errors.mean():.1%}", fontsize="medium")
    legend(ax)
    return titled(fig, dataset, "time stepping against event driven")


@figure(FIGURES, "aspect_ratio", variables=("aspect_ratio",), dims=("n_spheres",))
def aspect_ratio(dataset: xr.Dataset) -> Figure:
    """Aspect ratio A_r of the final cluster against N (Degond et al. 2024, Fig. 13).

    A straight line (A_r infinite) is left out of the mean and spread.
    """
    fig = ensemble_figure(dataset.aspect_ratio, "n_spheres", xscale="log", xlabel=N_LABEL,
                          ylabel="aspect ratio $A_r$")
    return titled(fig, dataset, "aspect ratio")


@figure(FIGURES, "orientation", variables=("orientation",), dims=("n_spheres",))
def orientation(dataset: xr.Dataset) -> Figure:
    """Angle between the cluster's orientation D and the x axis against N (Degond et al. 2024, Fig. 14).

    Every realisation is a dot, the ensemble mean and standard deviation an error bar; the
    point clouds of one N sit side by side.  Isotropic orientations in 2D spread the
    angle uniformly over 0-90 degrees.
    """
    x_component = flag_value(dataset.component.attrs, "x")
    angle = np.degrees(np.arccos(np.clip(abs(dataset.orientation.sel(component=x_component)), 0.0, 1.0)))
    fig, (ax,) = new_figure(1)
    n = angle["n_spheres"].values.astype(np.float64)
    listed = curves(angle, keep=("n_spheres",))
    for k, curve in enumerate(listed):
        part = angle.isel(curve.selection).transpose("n_spheres", REALIZATION)
        x = n * DODGE ** (k - (len(listed) - 1) / 2)
        ax.plot(np.repeat(x, part.sizes[REALIZATION]), part.values.ravel(), ".", color=curve.style["color"],
                alpha=0.4)
        mean, spread = ensemble(part)
        draw_curve(ax, x, mean.values, spread.values, curve)
    ax.set(xscale="log", xlabel=N_LABEL, ylabel="angle between $D$ and the x axis [degree]", ylim=(0, 90),
           yticks=(0, 30, 60, 90))
    legend(ax)
    return titled(fig, dataset, "orientation of the clusters")


@figure(FIGURES, "cluster", picture=True)
def cluster(dataset: xr.Dataset, task_file) -> Figure:
    """One task's final configuration, each cluster in its own colour (Degond et al. 2024, Figs. 4, 5, 12).

    Discs are drawn to scale in 2D; spheres in 3D are rendered as seen from above (along -z).
    """
    configuration = read_snapshot(task_file, ("spheres/position", "spheres/radius", "spheres/cluster"))
    position = configuration.arrays["spheres/position"]
    radius = configuration.arrays["spheres/radius"]
    label = configuration.arrays["spheres/cluster"]
    colours = distinct_colours(label)
    fig = Figure(figsize=(6.0, 6.0), layout="constrained")
    ax = fig.subplots()
    if position.shape[1] == 2:
        ax.add_collection(EllipseCollection(2 * radius, 2 * radius, np.zeros_like(radius), units="xy",
                                            offsets=position, offset_transform=ax.transData, facecolors=colours,
                                            edgecolors="0.2", linewidths=0.2))
    else:
        image, extent = render_spheres(position[:, 0], position[:, 1], -position[:, 2], radius, colours)
        ax.imshow(image, extent=extent, origin="lower", interpolation="nearest")
    lower, upper = configuration.box_lower[:2], configuration.box_upper[:2]
    ax.add_patch(Rectangle(lower, *(upper - lower), fill=False, edgecolor="0.3", linewidth=0.8))
    ax.set(xlim=(lower[0], upper[0]), ylim=(lower[1], upper[1]), aspect="equal", xlabel=position_label(dataset, "x"),
           ylabel=position_label(dataset, "y"))
    clusters = len(np.unique(label))
    return titled(fig, dataset, f"{task_text(dataset, task_file, configuration.attrs)}\n"
                                f"({len(radius)} spheres, {clusters} cluster{'s' if clusters > 1 else ''})")
