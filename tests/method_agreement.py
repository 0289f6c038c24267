"""The test of docs/ts-vs-ed.md: time stepping agrees with event driven on the same initial conditions."""

import numpy as np
import xarray as xr

from parsim.comparison import method_comparison
from parsim.output.dataset import decoded


def assert_time_stepping_agrees(dataset: xr.Dataset, contacts_ed: tuple, contacts_ts: tuple) -> list[dict]:
    """Every task reached one cluster; D_f within Fig. 11's bounds (5 % at every point, 3 % on average);
    N_c of each method within its open range (Fig. 7); A_r within 2.5 standard errors of the difference
    over the realisations.  Returns the rows of :func:`parsim.comparison.method_comparison`."""
    assert (dataset.n_clusters == 1).all()
    rows = method_comparison(dataset)
    errors = [row["e(D_f)"] for row in rows]
    assert max(errors) <= 0.05 and np.mean(errors) <= 0.03, errors
    for row in rows:
        assert contacts_ed[0] < row["N_c ED"] < contacts_ed[1] and contacts_ts[0] < row["N_c TS"] < contacts_ts[1], row
    named = decoded(dataset, ["method"])
    ed, ts = named.sel({"method": "ed"}).aspect_ratio, named.sel({"method": "ts"}).aspect_ratio
    spread = np.sqrt(ed.var("realization", ddof=1) / ed.sizes["realization"]
                     + ts.var("realization", ddof=1) / ts.sizes["realization"])
    assert (abs(ed.mean("realization") - ts.mean("realization")) <= 2.5 * spread).all()
    return rows
