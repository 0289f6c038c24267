"""The numbers of docs/reproduction.md, printed from the datasets of the papers' jobs.

Reads the datasets that ``parsim run`` wrote for the jobs of ``jobs/`` and prints, for each, the
numbers that docs/reproduction.md compares with the papers:

- ``topic2016_fig8`` (Topić & Pöschel 2016, Fig. 8): per shape, the mean filling height
  h = 2 z_cm at every trial angle with its standard error (std / sqrt(n), ddof 1), the variation of
  the means over the angles, (max − min) / mean of the means, and the difference between the
  largest and the smallest angle in combined standard errors;
- ``topic2016_fig12`` (Fig. 12): per shape, the mean spheres per second at every L, the largest
  and smallest of them and their ratio (a timing: it differs between runs and machines);
- ``degond2024_ts_vs_ed`` (Degond et al. 2024, section 4.2): the largest and mean e(D_f) of
  ``python -m parsim.comparison``, the range of N_c per method and N, of max dP/P_ED per N, the
  aspect ratio's TS − ED difference in standard errors of that difference (sqrt(SE_TS² + SE_ED²),
  non-finite A_r left out), the range of the mean |D_x|, and the mean task wall time per method,
  V_f and N with the least-squares exponent of ``parsim plot``'s ``wall_time`` figure (a timing).

The job is recognised by its variables and swept parameters, not by its name, so a copy of a
job with another seed or size is read the same way.  Each argument is a dataset or an output
folder (its finished dataset is read).

    python benchmarks/reproduction.py output/topic2016_fig8 output/topic2016_fig12 output/degond2024_ts_vs_ed
"""

import argparse
import os
import sys

import numpy as np
import xarray as xr

if __package__ in (None, ""):  # run as a script from a source tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir))

from parsim.comparison import method_comparison  # noqa: E402
from parsim.plots.aggregation import power_law  # noqa: E402
from parsim.output.dataset import decoded  # noqa: E402
from parsim.solver import flag_value  # noqa: E402

REALIZATION = "realization"


def mean_and_error(values: xr.DataArray) -> tuple[xr.DataArray, xr.DataArray]:
    """Ensemble mean and standard error of the mean over the realisations, non-finite values left out."""
    finite = values.where(np.isfinite(values))
    count = finite.count(REALIZATION)
    return finite.mean(REALIZATION), finite.std(REALIZATION, ddof=1) / np.sqrt(count)


def strings(coordinate: xr.DataArray) -> list[str]:
    """The values of a string coordinate, or of one coded by flag_values / flag_meanings."""
    if "flag_meanings" in coordinate.attrs:
        names = coordinate.attrs["flag_meanings"].split()
        codes = list(np.atleast_1d(coordinate.attrs["flag_values"]))
        return [names[codes.index(value)] for value in coordinate.values.tolist()]
    return [str(value) for value in coordinate.values.tolist()]


def per_shape(ds: xr.Dataset):
    """(shape name, the dataset at that shape) for each swept shape, or the one fixed shape."""
    if "shape" not in ds.dims:
        yield str(ds["shape"].values), ds
        return
    for index, name in enumerate(strings(ds["shape"])):
        yield name, ds.isel(shape=index)


def filling_height(ds: xr.Dataset) -> None:
    print(f"filling height h = 2 z_cm against the trial angle (Topić & Pöschel 2016, Fig. 8), "
          f"{ds.sizes[REALIZATION]} packings per point, seed {ds.attrs.get('job_seed')}")
    for name, part in per_shape(ds):
        mean, error = mean_and_error(part.filling_height)
        angles = part["trial_angle"].values
        print(f"  {name}:")
        for angle, m, e in zip(angles, mean.values, error.values):
            print(f"    trial angle {angle:8.0e}: h = {m:9.2f} ± {e:6.2f} ({100 * e / m:.2f} %)")
        relative = error.values / mean.values
        spread = (mean.values.max() - mean.values.min()) / mean.values.mean()
        low, high = int(np.argmin(angles)), int(np.argmax(angles))
        combined = np.hypot(error.values[low], error.values[high])
        print(f"    mean h {mean.values.mean():.1f}; the means vary by {100 * spread:.2f} % over the angles; "
              f"standard errors {100 * relative.min():.2f}–{100 * relative.max():.2f} %; "
              f"h(largest angle) − h(smallest) = {mean.values[high] - mean.values[low]:+.1f} "
              f"= {(mean.values[high] - mean.values[low]) / combined:+.1f} combined standard errors")


def efficiency(ds: xr.Dataset) -> None:
    print(f"spheres deposited per second against L (Topić & Pöschel 2016, Fig. 12; a timing), "
          f"{ds.sizes[REALIZATION]} realisations per point")
    for name, part in per_shape(ds):
        mean = part.spheres_per_second.mean(REALIZATION)
        sizes = part["shape_size"].values
        rates = ", ".join(f"L={size}: {rate:.0f}" for size, rate in zip(sizes, mean.values))
        fastest, slowest = int(np.argmax(mean.values)), int(np.argmin(mean.values))
        print(f"  {name}: {rates}")
        print(f"    max / min {mean.values.max() / mean.values.min():.2f} (fastest L = {sizes[fastest]}, "
              f"slowest L = {sizes[slowest]}), {mean.values.min():.0f} – {mean.values.max():.0f} spheres/s")


def ts_against_ed(ds: xr.Dataset) -> None:
    print(f"TS against ED (Degond et al. 2024, section 4.2), {ds.sizes[REALIZATION]} realisations per point")
    rows = method_comparison(ds)
    errors = np.array([row["e(D_f)"] for row in rows])
    print(f"  e(D_f): largest {errors.max():.1%}, mean {errors.mean():.1%}")
    named = decoded(ds, ["method"])  # the swept method is coded as CF flags
    ed, ts = named.sel({"method": "ed"}), named.sel({"method": "ts"})
    for n in ds["n_spheres"].values:
        point = {"n_spheres": n}
        n_c = {method: part.contact_number.sel(point).mean(REALIZATION).values
               for method, part in (("ED", ed), ("TS", ts))}
        d_p = [row["max dP/P_ED"] for row in rows if row["n_spheres"] == n]
        print(f"  N = {n:>6}: N_c ED {n_c['ED'].min():.3f}–{n_c['ED'].max():.3f}, "
              f"TS {n_c['TS'].min():.3f}–{n_c['TS'].max():.3f}; max dP/P_ED {min(d_p):.1%}–{max(d_p):.1%}")
    mean_ed, error_ed = mean_and_error(ed.aspect_ratio)
    mean_ts, error_ts = mean_and_error(ts.aspect_ratio)
    ratio = abs(mean_ts - mean_ed) / np.hypot(error_ts, error_ed)
    worst = ratio.where(ratio == ratio.max(), drop=True)
    print(f"  A_r: |TS − ED| / standard error of the difference at most {float(ratio.max()):.2f} "
          f"(N = {int(worst['n_spheres'].values[0])}, V_f = {float(worst['volume_fraction'].values[0])}); "
          f"within 2 at {int((ratio < 2).sum())} of {ratio.size} points")
    x = flag_value(ds.component.attrs, "x")
    d_x = abs(ds.orientation.sel(component=x)).mean(REALIZATION)
    print(f"  mean |D_x| per point: {float(d_x.min()):.3f} – {float(d_x.max()):.3f} (isotropic in 2D: 2/π = 0.637)")
    n = ds["n_spheres"].values.astype(np.float64)
    print("  mean task wall time [s] against N, and its least-squares exponent (the wall_time figure):")
    for method in named["method"].values:
        for vf in ds["volume_fraction"].values:
            mean = named.wall_time.sel({"method": method, "volume_fraction": vf}).mean(REALIZATION).values
            fit = power_law(n, mean)
            times = ", ".join(f"{t:.3g}" for t in mean)
            exponent = f"; exponent {fit[0]:.2f}" if fit else ""
            print(f"    {method} V_f = {vf:g}: {times}{exponent}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("datasets", nargs="+", help="datasets (.nc) of the jobs, or their output folders")
    args = parser.parse_args(argv)
    for path in args.datasets:
        if os.path.isdir(path):  # an output folder: its dataset
            found = [name for name in sorted(os.listdir(path))
                     if name.endswith(".nc") and not name.endswith(".partial.nc")]
            if len(found) != 1:
                print(f"{path}: no dataset (NAME.nc) in this folder; has the job finished?", file=sys.stderr)
                return 2
            path = os.path.join(path, found[0])
        with xr.open_dataset(path) as ds:
            ds = ds.load()
        print(f"{path} (job {ds.attrs.get('job_name')}, parsim {ds.attrs.get('parsim_version')}, "
              f"created {ds.attrs.get('date_created')}, {ds.attrs.get('mpi_size')} ranks)")
        if "filling_height" in ds and "trial_angle" in ds.dims:
            filling_height(ds)
        elif "spheres_per_second" in ds and "shape_size" in ds.dims:
            efficiency(ds)
        elif "fractal_dimension" in ds and "method" in ds.dims:
            ts_against_ed(ds)
        else:
            print("  not a dataset of topic2016_fig8, topic2016_fig12 or degond2024_ts_vs_ed "
                  "(trial_angle, shape_size or method swept)")
            return 2
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
