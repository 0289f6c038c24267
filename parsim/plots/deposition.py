"""Figures of deposition jobs, after Topić & Pöschel (2016)."""

import numpy as np
import xarray as xr
from matplotlib.figure import Figure

from parsim.plots.common import (BAND_ALPHA, axis_label, curves, ensemble, ensemble_figure, figure, legend,
                                 new_figure, position_label, read_snapshot, task_text, titled)
from parsim.plots.render import distinct_colours, render_spheres

FIGURES: dict = {}
SIDE_WINDOW = 1.2  # the side view shows at most this many box widths below the top


@figure(FIGURES, "filling_height", variables=("filling_height",), dims=("trial_angle",))
def filling_height(dataset: xr.Dataset) -> Figure:
    """Filling height h = 2 z_cm against the trial angle Δφ (Topić & Pöschel 2016, Fig. 8b, c).

    One panel per shape; ensemble mean with the standard deviation over the realisations as
    error bars, as in the paper.
    """
    fig = ensemble_figure(dataset.filling_height, "trial_angle", panel="shape", xscale="log",
                          xlabel=r"trial angle $\Delta\varphi$", ylabel="filling height $h$")
    return titled(fig, dataset, "filling height against the trial angle")


@figure(FIGURES, "efficiency", variables=("spheres_per_second",), dims=("shape_size",))
def efficiency(dataset: xr.Dataset) -> Figure:
    """Spheres deposited per second against the particle size L, per shape (Topić & Pöschel 2016, Fig. 12)."""
    fig = ensemble_figure(dataset.spheres_per_second, "shape_size", xlabel="particle size $L$",
                          ylabel="spheres deposited per second")
    return titled(fig, dataset, "efficiency of the deposition")


@figure(FIGURES, "packing_profile", variables=("packing_profile",))
def packing_profile(dataset: xr.Dataset) -> Figure:
    """Packing fraction φ(z) of horizontal slabs against the height z / h over the filling height h.

    Ensemble mean with a band of one standard deviation, one curve per swept point (the
    bulk, 0.25 h to 0.75 h, is where ``bulk_packing_fraction`` is measured).
    """
    fig = _ensemble_curves(dataset.packing_profile, "z_relative", r"packing fraction $\varphi$", "$z / h$",
                           vertical=True)
    return titled(fig, dataset, "packing fraction profile")


def _several_species(dataset: xr.Dataset) -> list[str]:
    return [] if dataset.sizes.get("species", 0) > 1 else ["a mixture: the job has one species"]


@figure(FIGURES, "species_profiles", variables=("species_packing_profile",), check=_several_species)
def species_profiles(dataset: xr.Dataset) -> Figure:
    """Each species' packing fraction φ_s(z) against z / h: how a mixture or a stratified sediment is
    built up, one curve per species (and swept point), with the total φ(z) of the deposited particles."""
    fig = _ensemble_curves(dataset.species_packing_profile, "z_relative", r"packing fraction $\varphi_s$",
                           "$z / h$", vertical=True)
    return titled(fig, dataset, f"species profiles, segregation {float(dataset.segregation_index.mean()):.2f}")


@figure(FIGURES, "long_axes", variables=("orientation_density",))
def long_axes(dataset: xr.Dataset) -> Figure:
    """Probability density of the angle θ between the bulk particles' long axes and the vertical,
    against sin θ of isotropic orientations; the nematic order S and <P2(cos θ)> in the title."""
    variable = dataset.orientation_density
    fig = _ensemble_curves(variable, "angle_to_vertical", "probability density", r"angle $\theta$ to the vertical")
    angle = np.linspace(0.0, 0.5 * np.pi, 200)
    fig.axes[0].plot(angle, np.sin(angle), color="0.4", linestyle=":", label=r"isotropic, $\sin\theta$")
    legend(fig.axes[0])
    return titled(fig, dataset, f"long axes: S = {float(dataset.nematic_order.mean()):.2f}, "
                                rf"$\langle P_2 \rangle$ = {float(dataset.vertical_order.mean()):.2f}")


@figure(FIGURES, "radial_distribution", variables=("radial_distribution",))
def radial_distribution(dataset: xr.Dataset) -> Figure:
    """Radial distribution function g(r) of the bulk particles' centres of mass against r over the
    mean volume-equivalent diameter; 1 is the ideal gas of the same density."""
    fig = _ensemble_curves(dataset.radial_distribution, "r_relative", "$g(r)$", "$r / d$")
    fig.axes[0].axhline(1.0, color="0.4", linestyle=":", linewidth=0.8)
    return titled(fig, dataset, "g(r) of the centres of mass")


def _ensemble_curves(variable: xr.DataArray, along: str, value_label: str, along_label: str,
                     vertical: bool = False) -> Figure:
    """One panel: ensemble mean of ``variable`` along ``along`` with a band of one standard
    deviation, one curve per value of the other dimensions; ``vertical`` puts ``along`` upright."""
    fig, (ax,) = new_figure(1)
    coordinate = variable[along]
    for curve in curves(variable, keep=(along,)):
        mean, spread = ensemble(variable.isel(curve.selection))
        if vertical:
            ax.plot(mean, coordinate, label=curve.label, **curve.style)
            ax.fill_betweenx(coordinate, mean - spread, mean + spread, color=curve.style["color"],
                             alpha=BAND_ALPHA, linewidth=0)
        else:
            ax.plot(coordinate, mean, label=curve.label, **curve.style)
            ax.fill_between(coordinate, mean - spread, mean + spread, color=curve.style["color"],
                            alpha=BAND_ALPHA, linewidth=0)
    value_text, along_text = axis_label(variable, value_label), axis_label(coordinate, along_label)
    if vertical:
        ax.set(xlabel=value_text, ylabel=along_text)
    else:
        ax.set(xlabel=along_text, ylabel=value_text)
    legend(ax)
    return fig


@figure(FIGURES, "sediment", picture=True)
def sediment(dataset: xr.Dataset, task_file) -> Figure:
    """One task's sediment seen from the side and from above, each particle in its own colour
    (Topić & Pöschel 2016, Figs. 11, 13, 14).

    Along periodic sides the spheres are wrapped into the box, with the images of those that
    cross a side.  Of a sediment taller than SIDE_WINDOW box widths, the side view shows the
    top SIDE_WINDOW box widths.
    """
    configuration = read_snapshot(task_file, ("spheres/position", "spheres/radius", "spheres/particle"))
    particle = configuration.arrays["spheres/particle"]
    lower, upper = configuration.box_lower, configuration.box_upper
    radius = configuration.arrays["spheres/radius"]
    position, index = periodic_images(configuration.arrays["spheres/position"], radius, lower, upper,
                                      configuration.periodic)
    x, y, z = position.T
    radius, colours = radius[index], distinct_colours(particle)[index]
    floor = configuration.attrs.get("floor_z", 0.0)
    bottom = max(floor, upper[2] - SIDE_WINDOW * (upper[0] - lower[0]))
    fig = Figure(figsize=(11.0, 5.0), layout="constrained")
    side, top = fig.subplots(1, 2)
    window = z + radius > bottom
    x_label = position_label(dataset, "x")
    _draw_view(side, x[window], z[window], y[window], radius[window], colours[window], x_label)
    side.axhline(floor, color="0.3", linewidth=0.8)
    side.set(xlim=(lower[0], upper[0]), ylim=(bottom, upper[2]), ylabel=position_label(dataset, "z"))
    side.set_title("side" if bottom == floor else "side, top of the sediment", fontsize="medium")
    _draw_view(top, x, y, -z, radius, colours, x_label)
    top.set(xlim=(lower[0], upper[0]), ylim=(lower[1], upper[1]), ylabel=position_label(dataset, "y"))
    top.set_title("top", fontsize="medium")
    return titled(fig, dataset, f"{task_text(dataset, task_file, configuration.attrs)}\n"
                                f"({len(particle)} spheres in {particle.max() + 1} particles)")


def _draw_view(ax, u, v, depth, radius, colours, xlabel: str) -> None:
    image, extent = render_spheres(u, v, depth, radius, colours)
    ax.imshow(image, extent=extent, origin="lower", interpolation="nearest")
    ax.set(xlabel=xlabel, aspect="equal")


def periodic_images(position, radius, lower, upper, periodic) -> tuple[np.ndarray, np.ndarray]:
    """Centres wrapped into the box along its periodic axes, plus the images of the spheres that
    cross a periodic side; returns the centres and the index of the sphere each one shows."""
    position = np.array(position, dtype=np.float64)
    index = np.arange(len(position))
    for axis in np.flatnonzero(periodic):
        length = upper[axis] - lower[axis]
        position[:, axis] = lower[axis] + np.mod(position[:, axis] - lower[axis], length)
        low = position[:, axis] < lower[axis] + radius[index]
        high = position[:, axis] > upper[axis] - radius[index]
        shift = length * np.eye(position.shape[1])[axis]
        position = np.concatenate([position, position[low] + shift, position[high] - shift])
        index = np.concatenate([index, index[low], index[high]])
    return position, index
