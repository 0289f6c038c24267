"""The fractal law of aggregates through their radius of gyration, N = k_f (R_g / a)^D_f.

The aerosol and soot literature (FracVAL, MCAC, and the tunable aggregation it descends from)
reports an aggregate's fractal dimension D_f together with its prefactor k_f, both from the
radius of gyration of aggregates of N monomers of radius a.  :func:`fractal_law` fits them on a
dataset of aggregation tasks by ordinary least squares on

    log N = log k_f + D_f log(R_g / a),

one fit per point of the sweep over its realisations and its values of ``n_spheres`` (which must
be a dimension of the dataset with two values or more), with ``a`` the point's ``radius`` (the
median radius of lognormal monomers).  Only tasks that end as one cluster enter the fit: R_g is
then the aggregate's.  The standard errors are those of the least-squares slope and intercept
(residual variance over n - 2 degrees of freedom); k_f's is propagated from log k_f's,
se(k_f) = k_f se(log k_f).

At a fixed volume fraction the final cluster of the paper's runs spans its box, whose side grows as
N^(1/d): the law fitted across N then measures how the box fills, D_f close to d, rather than the
fractal dimension of free aggregates, which eq. 4.8's box counting measures within one cluster.
"""

import numpy as np
import xarray as xr

#: Dimensions a fit runs over: every realisation of every N of a point.
FIT_DIMS = ("n_spheres", "realization")


def fractal_law(dataset: xr.Dataset) -> xr.Dataset:
    """D_f and k_f of ``N = k_f (R_g / a)^D_f`` with their standard errors, per point of ``dataset``.

    ``dataset`` is an aggregation job's dataset (``xarray.open_dataset`` of its ``dataset.nc``) with
    ``n_spheres`` among its dimensions.  Returns a dataset over the remaining dimensions holding
    ``fractal_dimension``, ``fractal_dimension_error``, ``fractal_prefactor``, ``fractal_prefactor_error``
    and ``tasks`` (how many tasks entered each fit); a point with fewer than three tasks or a single N
    among them gets NaN.  Raises ValueError naming what is missing when the dataset cannot be fitted.
    """
    for name in ("radius_of_gyration", "n_clusters", "radius"):
        if name not in dataset.variables:
            raise ValueError(f"fractal_law needs {name!r} in the dataset: an aggregation job's dataset has it")
    if "n_spheres" not in dataset.dims or dataset.sizes["n_spheres"] < 2:
        values = np.atleast_1d(dataset["n_spheres"].values) if "n_spheres" in dataset.variables else []
        raise ValueError(f"fractal_law fits across N: it needs n_spheres swept over two values or more; this dataset "
                         f"has n_spheres = {list(map(int, values))}")
    dims = [dim for dim in FIT_DIMS if dim in dataset.dims]
    n = dataset["n_spheres"].astype(float)
    rg = dataset["radius_of_gyration"]
    x = np.log(rg / dataset["radius"])
    y = np.log(n).broadcast_like(x)
    used = (dataset["n_clusters"] == 1) & np.isfinite(x) & (rg > 0)
    x, y = x.where(used), y.where(used)
    count = used.sum(dims)
    mean_x, mean_y = x.mean(dims), y.mean(dims)
    sxx = ((x - mean_x) ** 2).sum(dims)
    slope = ((x - mean_x) * (y - mean_y)).sum(dims) / sxx
    intercept = mean_y - slope * mean_x
    residual = ((y - intercept - slope * x) ** 2).sum(dims) / (count - 2)
    distinct = (y.max(dims) > y.min(dims))
    fitted = (count >= 3) & distinct & (sxx > 0)
    slope_error = np.sqrt(residual / sxx)
    intercept_error = np.sqrt(residual * (1.0 / count + mean_x**2 / sxx))
    prefactor = np.exp(intercept)
    law = xr.Dataset({
        "fractal_dimension": slope.where(fitted).assign_attrs(
            units="1", long_name="fractal dimension D_f of N = k_f (R_g / a)^D_f, least squares over N and realisations"),
        "fractal_dimension_error": slope_error.where(fitted).assign_attrs(
            units="1", long_name="standard error of D_f"),
        "fractal_prefactor": prefactor.where(fitted).assign_attrs(
            units="1", long_name="fractal prefactor k_f of N = k_f (R_g / a)^D_f"),
        "fractal_prefactor_error": (prefactor * intercept_error).where(fitted).assign_attrs(
            units="1", long_name="standard error of k_f, k_f se(log k_f)"),
        "tasks": count.assign_attrs(units="1", long_name="tasks ending as one cluster that entered the fit"),
    })
    return law.drop_vars([name for name in law.coords if name in FIT_DIMS], errors="ignore")
