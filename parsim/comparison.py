"""TS against ED, point by point, from one aggregation dataset with ``method`` swept.

Section 4.2 of Degond et al. 2024 compares the methods by the fractal dimension (Fig. 11: relative
error ``e = |D_f,TS - D_f,ED| / D_f,ED`` at most 5 %, below 3 % on average), the contact number
N_c (Fig. 7, both near 0.5), the pair distribution P(r) (Fig. 8) and the aspect ratio and
orientation (supplementary B).  :func:`method_comparison` computes those numbers from the ensemble
means; ``python -m parsim.comparison DATASET.nc`` prints them as a Markdown table.
"""

import sys

import numpy as np
import xarray as xr

from parsim.output.dataset import decoded
from parsim.solver import flag_value, named_values

COLUMNS = ("n_spheres", "volume_fraction", "D_f ED", "D_f TS", "e(D_f)", "N_c ED", "N_c TS",
           "max dP/P_ED", "A_r ED", "A_r TS", "mean abs D_x ED", "mean abs D_x TS")


def method_comparison(dataset: xr.Dataset) -> list[dict]:
    """One row per (n_spheres, volume_fraction): ensemble means of both methods and their differences.

    ``max dP/P_ED`` is the largest relative difference of the mean P(r) over r; ``mean abs D_x`` the
    mean absolute x component of the orientation (isotropic orientations give 2/pi = 0.64 in 2D, 1/2 in 3D).
    """
    if "method" not in dataset.dims or not {"ed", "ts"} <= set(named_values(dataset["method"])):
        raise ValueError("the dataset must have a 'method' dimension holding 'ed' and 'ts' (sweep method)")
    dataset = decoded(dataset, ["method"])
    mean = dataset.mean("realization")
    ed, ts = mean.sel({"method": "ed"}), mean.sel({"method": "ts"})
    x_component = flag_value(dataset.component.attrs, "x")
    orientation_ed = abs(dataset.orientation.sel({"method": "ed", "component": x_component})).mean("realization")
    orientation_ts = abs(dataset.orientation.sel({"method": "ts", "component": x_component})).mean("realization")
    rows = []
    swept = [name for name in ("n_spheres", "volume_fraction") if name in dataset.dims]
    for n in np.atleast_1d(dataset["n_spheres"].values):
        for vf in np.atleast_1d(dataset["volume_fraction"].values):
            point = {name: value for name, value in (("n_spheres", n), ("volume_fraction", vf)) if name in swept}
            d_ed = float(ed.fractal_dimension.sel(point))
            d_ts = float(ts.fractal_dimension.sel(point))
            p_ed = ed.pair_distribution.sel(point).values
            p_ts = ts.pair_distribution.sel(point).values
            rows.append({
                "n_spheres": int(n), "volume_fraction": float(vf), "D_f ED": d_ed, "D_f TS": d_ts,
                "e(D_f)": abs(d_ts - d_ed) / d_ed,
                "N_c ED": float(ed.contact_number.sel(point)), "N_c TS": float(ts.contact_number.sel(point)),
                "max dP/P_ED": float(np.max(np.abs(p_ts - p_ed) / p_ed)),
                "A_r ED": float(ed.aspect_ratio.sel(point)), "A_r TS": float(ts.aspect_ratio.sel(point)),
                "mean abs D_x ED": float(orientation_ed.sel(point)), "mean abs D_x TS": float(orientation_ts.sel(point)),
            })
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for row in rows:
        cells = [f"{row[c]:.1%}" if c.startswith(("e(", "max")) else
                 (str(row[c]) if c == "n_spheres" else f"{row[c]:.3g}") for c in COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    errors = np.array([row["e(D_f)"] for row in rows])
    lines.append("")
    lines.append(f"e(D_f): largest {errors.max():.1%}, mean {errors.mean():.1%} (paper: about 5 % and below 3 %)")
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m parsim.comparison DATASET.nc", file=sys.stderr)
        return 2
    with xr.open_dataset(argv[0]) as dataset:
        print(markdown(method_comparison(dataset.load())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
