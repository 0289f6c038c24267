"""What the figures share: registration and needs, ensemble statistics, curves, labels, saving.

Figures are :class:`matplotlib.figure.Figure` objects made without pyplot: no window and
no global list of open figures; ``savefig`` writes PNG through the Agg canvas and PDF
through the PDF canvas.
"""

import functools
import itertools
import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator, NullFormatter

from parsim.errors import PlotError
from parsim.output.snapshot import read_configuration

REALIZATION = "realization"
LINE_STYLE_DIMENSION = "method"  # ED and TS of one parameter point: one colour, two line styles
LINE_STYLES = ("-", "--", ":", "-.")
BAND_ALPHA = 0.2
PANEL_SIZE = (4.8, 3.6)  # inches
MAX_COLUMNS = 3
PNG_DPI = 150
FORMATS = (".png", ".pdf")
UNIT_TEXT = {"-1": "⁻¹"}  # as axes show units


@dataclass(frozen=True)
class FigureSpec:
    """A figure ``parsim plot`` can draw, and what it needs from the outputs.

    ``draw(dataset)`` returns the figure; a ``picture`` is ``draw(dataset, task_file)``.
    ``variables`` must be in the dataset with some finite value, ``dims`` must be
    dimensions of it (swept parameters), and ``check(dataset)`` lists further unmet needs.
    """

    name: str
    draw: Callable[..., Figure]
    variables: tuple[str, ...] = ()
    dims: tuple[str, ...] = ()
    check: Callable[[xr.Dataset], list[str]] | None = None
    picture: bool = False

    def missing(self, dataset: xr.Dataset) -> list[str]:
        """What the dataset lacks for this figure, one phrase per need (empty: it can be drawn)."""
        needs = [f"variable {name!r}" for name in self.variables if name not in dataset.data_vars]
        needs += [f"finite values of {name!r}" for name in self.variables
                  if name in dataset.data_vars and not np.isfinite(dataset[name].values).any()]
        needs += [f"dimension {name!r} (sweep {name} in the job)" for name in self.dims if name not in dataset.dims]
        if self.check is not None and not needs:
            needs += self.check(dataset)
        return needs


def figure(registry: dict, name: str, *, variables=(), dims=(), check=None, picture=False):
    """Register the decorated function in ``registry`` as figure ``name``; it checks its needs first."""
    def register(draw):
        @functools.wraps(draw)
        def checked(dataset, *args):
            require(registry[name], dataset)
            return draw(dataset, *args)

        registry[name] = FigureSpec(name, checked, tuple(variables), tuple(dims), check, picture)
        return checked
    return register


def require(spec: FigureSpec, dataset: xr.Dataset) -> None:
    missing = spec.missing(dataset)
    if missing:
        raise PlotError(f"figure {spec.name!r} cannot be drawn: the dataset lacks {'; '.join(missing)}")


def read_snapshot(task_file: Path, arrays: tuple[str, ...]):
    """The configuration in a task file, which must hold ``arrays``."""
    try:
        configuration = read_configuration(task_file)
    except OSError as error:
        raise PlotError(f"cannot read task file {task_file}: {error}") from None
    missing = [name for name in arrays if name not in configuration.arrays]
    if missing:
        raise PlotError(f"task file {task_file} lacks {', '.join(missing)}")
    return configuration


def ensemble(variable: xr.DataArray) -> tuple[xr.DataArray, xr.DataArray]:
    """Mean and sample standard deviation over the realisations, non-finite values left out."""
    finite = variable.where(np.isfinite(variable))
    ddof = 1 if variable.sizes[REALIZATION] > 1 else 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a point without finite values is NaN: a gap
        return finite.mean(REALIZATION), finite.std(REALIZATION, ddof=ddof)


@dataclass(frozen=True)
class Curve:
    """One curve: indices of the swept dimensions it fixes, its legend entry and line style."""

    selection: dict[str, int]
    label: str | None
    style: dict


def curves(variable: xr.DataArray, keep: tuple[str, ...]) -> list[Curve]:
    """One curve per combination of values of the dimensions outside ``keep`` and realization.

    The legend names the swept parameters and their values; ``method`` sets the line
    style, the other dimensions the colour.
    """
    dims = [d for d in variable.dims if d not in keep and d != REALIZATION]
    colour_dims = [d for d in dims if d != LINE_STYLE_DIMENSION]
    result = []
    for index in itertools.product(*(range(variable.sizes[d]) for d in dims)):
        selection = dict(zip(dims, index))
        colour = int(np.ravel_multi_index([selection[d] for d in colour_dims],
                                          [variable.sizes[d] for d in colour_dims])) if colour_dims else 0
        style = {"color": f"C{colour % 10}",
                 "linestyle": LINE_STYLES[selection.get(LINE_STYLE_DIMENSION, 0) % len(LINE_STYLES)]}
        label = ", ".join(f"{d} = {coordinate_text(variable[d], i)}" for d, i in selection.items())
        result.append(Curve(selection, label or None, style))
    return result


def coordinate_text(coordinate: xr.DataArray, index: int) -> str:
    """Value ``index`` of a coordinate as a legend shows it: its name for a coded one (flag_meanings)."""
    meanings = coordinate.attrs.get("flag_meanings")
    return meanings.split()[index] if meanings else value_text(coordinate.values[index])


def value_text(value) -> str:
    return f"{value:g}" if isinstance(value, (float, np.floating)) else str(value)


def units_text(units: str | None) -> str | None:
    """Units as an axis shows them; None for a dimensionless quantity."""
    if units in (None, "", "1"):
        return None
    for name, text in UNIT_TEXT.items():
        units = units.replace(name, text)
    return units


def position_label(dataset: xr.Dataset, axis: str) -> str:
    """"x [m]": a position axis of a pictured task, in the job's length unit."""
    return f"{axis} [{dataset.attrs['length_unit']}]"


def axis_label(variable: xr.DataArray, text: str | None = None) -> str:
    """``text`` (default: the variable's long_name) with the variable's units in brackets."""
    text = text or variable.attrs.get("long_name", variable.name)
    units = units_text(variable.attrs.get("units"))
    return f"{text} [{units}]" if units else text


def new_figure(count: int) -> tuple[Figure, list]:
    """A figure with ``count`` axes on a grid of at most MAX_COLUMNS columns."""
    columns = min(count, MAX_COLUMNS)
    rows = math.ceil(count / columns)
    fig = Figure(figsize=(PANEL_SIZE[0] * columns, PANEL_SIZE[1] * rows), layout="constrained")
    axes = list(fig.subplots(rows, columns, squeeze=False).ravel())
    for unused in axes[count:]:
        fig.delaxes(unused)
    return fig, axes[:count]


def panels(variable: xr.DataArray, dim: str | None) -> tuple[Figure, list[tuple]]:
    """A figure with one panel per value of ``dim`` (a single panel if the variable lacks it).

    Returns the figure and (axes, the variable at that value) pairs.
    """
    if dim not in variable.dims:
        fig, axes = new_figure(1)
        return fig, [(axes[0], variable)]
    fig, axes = new_figure(variable.sizes[dim])
    pairs = []
    for i, ax in enumerate(axes):
        ax.set_title(f"{dim} = {value_text(variable[dim].values[i])}", fontsize="medium")
        pairs.append((ax, variable.isel({dim: i})))
    return fig, pairs


def draw_curve(ax, x, mean, spread, curve: Curve, band: bool = False) -> None:
    """The ensemble mean against ``x`` with the spread as error bars, or as a band."""
    if band:
        ax.plot(x, mean, label=curve.label, **curve.style)
        ax.fill_between(x, mean - spread, mean + spread, color=curve.style["color"], alpha=BAND_ALPHA, linewidth=0)
    else:
        ax.errorbar(x, mean, yerr=spread, marker="o", markersize=4, capsize=3, label=curve.label, **curve.style)


def legend(ax) -> None:
    if ax.get_legend_handles_labels()[1]:
        ax.legend(fontsize="small")


def ensemble_figure(variable: xr.DataArray, x: str, *, panel: str | None = None, band: bool = False,
                    xlabel: str | None = None, ylabel: str | None = None, xscale: str = "linear",
                    yscale: str = "linear") -> Figure:
    """``variable`` against its dimension ``x``: ensemble mean and spread, one curve per swept point."""
    fig, pairs = panels(variable, panel)
    for ax, part in pairs:
        for curve in curves(part, keep=(x,)):
            mean, spread = ensemble(part.isel(curve.selection))
            draw_curve(ax, part[x].values, mean.values, spread.values, curve, band)
        ax.set(xscale=xscale, yscale=yscale, xlabel=axis_label(variable[x], xlabel),
               ylabel=axis_label(variable, ylabel))
        if xscale == "log":
            ax.xaxis.set_minor_formatter(NullFormatter())  # labelled minor ticks overlap below a decade
        elif np.issubdtype(variable[x].dtype, np.integer):
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        legend(ax)
    return fig


def titled(fig: Figure, dataset: xr.Dataset, text: str) -> Figure:
    """``fig`` with a title naming the job and what the figure shows."""
    job = dataset.attrs.get("job_name")
    fig.suptitle(f"{job}: {text}" if job else text, fontsize="medium")
    return fig


def task_text(dataset: xr.Dataset, task_file: Path, attrs: dict) -> str:
    """"task LABEL: name = value, ..." for the swept parameters of a pictured task."""
    swept = [d for d in dataset.dims if d in attrs and d != REALIZATION]
    point = ", ".join(f"{d} = {value_text(attrs[d])}" for d in swept)
    return f"task {Path(task_file).stem}" + (f": {point}" if point else "")


def image_paths(target: Path) -> list[Path]:
    """The PNG and PDF files for ``target``: target.png and target.pdf, or target itself if it
    ends in .png or .pdf, and the other format beside it."""
    target = Path(target)
    suffix = target.suffix.lower()
    if suffix in FORMATS:
        other = FORMATS[1 - FORMATS.index(suffix)]
        return [target, target.with_suffix(other)]
    return [target.with_name(target.name + extension) for extension in FORMATS]


def save(fig: Figure, target: Path) -> list[Path]:
    """Write ``fig`` as PNG and PDF (see :func:`image_paths`); returns the files."""
    paths = image_paths(target)
    paths[0].parent.mkdir(parents=True, exist_ok=True)
    for path in paths:
        fig.savefig(path, dpi=PNG_DPI)
    return paths
