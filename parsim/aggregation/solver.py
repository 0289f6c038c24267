"""Ballistic aggregation of hard spheres (Degond, Dimarco, Ferreira & Hecht 2024).

One task: N spheres on a lattice filling the box [0, L]^d with random velocities
(section 4.1, or the supplementary's variant), aggregated until one cluster
remains (section 2), then the shape statistics of section 4.2 measured on the
final configuration.  ``method = "ed"`` is the exact event-driven method,
``method = "ts"`` the time-stepping method with the DAHA minimiser (section 3);
``method`` does not enter the seed, so both start from the same initial condition.

On a group of several ranks (``parsim run --ranks-per-task K``) a TS task is
decomposed over the group's ranks (:class:`parsim.aggregation.tiled.DecomposedDomain`), or,
in a box too small for a block of tiles per rank, run whole in one tile on every rank of the
group (the serial result); an ED task is serial: the group's rank 0 computes it and the other
ranks wait.
"""

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from parsim.core.ed import simulate_ed
from parsim.core.initial import (box_length_for_volume_fraction, isotropic_velocities, lattice_positions,
                                 lattice_sites_per_side, lattice_spacing, uniform_cube_velocities)
from parsim.core.scattering import structure_factor
from parsim.core.statistics import MIN_FIT_BOX_SIZES, cluster_statistics, fit_box_sizes, pair_distribution_grid
from parsim.core.ts import FORMULATIONS, DahaParameters, MinimiserFailure, simulate_ts
from parsim.core.ts.rare import compile_rare_kernels
from parsim.errors import JobError, NumericalError
from parsim.parameters import LARGEST_QUANTITY, REQUIRED, Parameter
from parsim.phases import phase
from parsim.solver import (LENGTH_UNITS, MASS_UNITS, SPEED_UNITS, TIME_UNITS, Configuration, Coordinate, Solver,
                           Statistic, TaskResult, coded_coordinate, flag_attributes)

if TYPE_CHECKING:
    from mpi4py import MPI

PAPER_INITIAL_CONDITION = "lattice_isotropic"  # section 4.1: lattice filling the box, eq. 4.3 velocities
SUPPLEMENTARY_INITIAL_CONDITION = "unit_lattice_uniform"  # supplementary A: spacing 1, V uniform in [-1/2, 1/2]^d
STOP_REASONS = ("single_cluster", "max_time", "max_events")
COMPONENTS = ("x", "y", "z")  # names of the Cartesian components, coded 0, 1, 2 in the dataset
_DAHA = DahaParameters()
BYTES_PER_SPHERE = 1536  # one task's memory per sphere, see memory()
WARM_UP_SIDE = {2: 4, 3: 3}  # spheres per side of the warm-up's lattice: 16 discs, 27 spheres
# Upper bounds of keys beyond which a value means nothing and only costs: a contact at 10 R is no
# contact, and the search for it grows as the factor to the power d; P(r) sampled at more than
# 10^4 points on 2R..20R resolves nothing a cluster has; an attraction beyond 20 R reaches across
# whole clusters; the DAHA coefficients (default 0.3 to 30) are unstable far below 10^6.
MAX_CONTACT_FACTOR = 10.0
MAX_PAIR_DISTRIBUTION_POINTS = 10_000
MAX_ATTRACTION_RANGE = 20.0
MAX_DAHA_COEFFICIENT = 1e6
MAX_STRUCTURE_FACTOR_POINTS = 10_000
#: A geometric standard deviation beyond which lognormal radii span more than a factor e^6 within two
#: standard deviations: the aerosol literature uses 1.1-1.5, and a cell list sized by the largest of
#: such radii holds most spheres in one cell.
MAX_RADIUS_GEOMETRIC_STD = 3.0
RADIUS_DISTRIBUTIONS = ("monodisperse", "lognormal")
WARM_UP_GEOMETRIC_STD = 1.0 + 1e-6


def _reads_ts(params: dict) -> bool:
    return params["method"] == "ts"


def _reads_radius_spread(params: dict) -> bool:
    return params["radius_distribution"] == "lognormal"


def _reads_speed(params: dict) -> bool:
    """Whether a task sets its velocities from ``speed`` (the supplementary initial condition does not)."""
    return params["initial_condition"] == PAPER_INITIAL_CONDITION


def _ts(name, type_, default, units, description, **limits):
    """A parameter read by the time-stepping method only (never part of the seed)."""
    return Parameter(name, type_, default, units, f"(ts only) {description}", affects_seed=False,
                     read_when=_reads_ts, **limits)


PARAMETERS = (
    Parameter("method", str, "ed", "1", "aggregation method: 'ed' event-driven (exact), "
              "'ts' time stepping with the DAHA minimiser (section 3)",
              choices=("ed", "ts"), affects_seed=False),
    Parameter("dimension", int, 2, "1", "space dimension d", choices=(2, 3), sweepable=False),
    Parameter("n_spheres", int, REQUIRED, "1", "number of spheres N", low=2),
    Parameter("volume_fraction", float, None, "1",
              "volume fraction V_f; sets the box length L = R (N pi / V_f)^(1/2) in 2D (Table 1), "
              "L = R (4 pi N / (3 V_f))^(1/3) in 3D",
              low=0.0, high=1.0, low_inclusive=False, high_inclusive=False),
    Parameter("initial_condition", str, PAPER_INITIAL_CONDITION, "1",
              "initial condition: 'lattice_isotropic' (section 4.1: lattice filling the box, speeds |V|, "
              "uniformly random directions, eq. 4.3) or 'unit_lattice_uniform' (supplementary A: lattice "
              "of spacing 1, box length ceil(N^(1/d)), velocities uniform in [-1/2, 1/2]^d)",
              choices=(PAPER_INITIAL_CONDITION, SUPPLEMENTARY_INITIAL_CONDITION)),
    Parameter("radius", float, 0.2, LENGTH_UNITS, "sphere radius R (the median radius of lognormal radii)",
              low=0.0, low_inclusive=False, high=LARGEST_QUANTITY),
    # Not in the seed: points that differ in their radii alone share positions and velocities, and draw
    # the same normal deviates for their radii, so sigma_g = 1 is the monodisperse run bit for bit.
    Parameter("radius_distribution", str, "monodisperse", "1", "monomer radii: all equal to radius, or "
              "lognormal, r = radius exp(ln(sigma_g) Z) with Z standard normal (FracVAL, MCAC)",
              choices=RADIUS_DISTRIBUTIONS, affects_seed=False),
    Parameter("radius_geometric_std", float, 1.0, "1", "geometric standard deviation sigma_g of lognormal radii "
              "(1: all equal)", low=1.0, high=MAX_RADIUS_GEOMETRIC_STD, affects_seed=False,
              read_when=_reads_radius_spread),
    Parameter("mass", float, 1.0, MASS_UNITS, "sphere mass m (of a monomer of radius R; with unequal radii "
              "m (r / R)^d, one density)", low=0.0, low_inclusive=False, high=LARGEST_QUANTITY),
    Parameter("speed", float, 1.0, SPEED_UNITS, "initial speed |V| (eq. 4.3)",
              low=0.0, low_inclusive=False, high=LARGEST_QUANTITY, read_when=_reads_speed),
    Parameter("max_time", float, math.inf, TIME_UNITS, "stop at this time if several clusters remain",
              low=0.0, low_inclusive=False, high=math.inf),
    Parameter("max_events", int, 10**10, "1",
              "stop after this many events (ed) or time steps (ts) if several clusters remain", low=1),
    Parameter("contact_factor", float, 2.1, "1", "alpha_R of eq. 4.6: centres closer than alpha_R R are in contact",
              low=2.0, high=MAX_CONTACT_FACTOR),
    Parameter("pair_distribution_points", int, 72, "1", "number of r values of P(r) on 2R < r <= 20R (eq. 4.7)",
              low=2, high=MAX_PAIR_DISTRIBUTION_POINTS, sweepable=False),
    Parameter("box_levels", int, 12, "1", "box-counting levels m = 1..box_levels, eps_m = L / 2^m (eq. 4.8)",
              low=2, high=30, sweepable=False),
    # Off by default: Debye's sum visits every pair, 7 s at N = 4e4 on one core where the run itself takes 1-5 s.
    Parameter("compute_structure_factor", bool, False, "1", "compute the static structure factor S(q) of the final "
              "configuration (Debye's formula over all pairs, O(N^2); the statistic structure_factor is NaN when "
              "false)", affects_seed=False),
    Parameter("structure_factor_points", int, 24, "1", "number of q values of S(q), log-spaced from "
              "structure_factor_q_min to structure_factor_q_max", low=2, high=MAX_STRUCTURE_FACTOR_POINTS,
              sweepable=False),
    Parameter("structure_factor_q_min", float, 0.01, "1", "smallest q of S(q), in units of 1/R", low=0.0,
              low_inclusive=False, high=LARGEST_QUANTITY, sweepable=False),
    Parameter("structure_factor_q_max", float, 2.0, "1", "largest q of S(q), in units of 1/R", low=0.0,
              low_inclusive=False, high=LARGEST_QUANTITY, sweepable=False),
    _ts("time_step_factor", float, 0.005, "1", "dt(0) = factor L / max|V| (Table 1: 0.005, 0.01, 0.015); "
        "dt grows as ln(mean cluster size) to 2 dt(0) at one cluster", low=0.0, low_inclusive=False, high=1.0),
    _ts("formulation", str, "almost_rigid", "1", "'almost_rigid' (section 3.3: tiles, local attraction) or "
        "'non_rigid' (section 3.1: whole interacting clusters move)", choices=FORMULATIONS),
    _ts("attraction_range", float, 4.0, "1", "Delta_W of eq. 3.30 in units of R (almost_rigid)",
        low=2.0, high=MAX_ATTRACTION_RANGE),
    _ts("daha_damping", float, _DAHA.damping, "1", "DAHA damping c (c_bar of eq. 3.29 if daha_dynamic); "
        "eq. 4.1 has 1.3, which with daha_penalty 0.3 is unstable", low=0.0, low_inclusive=False,
        high=MAX_DAHA_COEFFICIENT),
    _ts("daha_step", float, _DAHA.step, "1", "DAHA artificial time step delta (eq. 4.1)", low=0.0,
        low_inclusive=False, high=1.0),
    _ts("daha_attraction", float, _DAHA.attraction, "1", "DAHA alpha (eq. 4.1)", low=0.0, low_inclusive=False,
        high=MAX_DAHA_COEFFICIENT),
    _ts("daha_penalty", float, _DAHA.penalty, "1", "DAHA gamma; eq. 4.1 has 0.3", low=0.0,
        high=MAX_DAHA_COEFFICIENT),
    _ts("daha_multiplier_rate", float, _DAHA.multiplier_rate, "1", "DAHA beta (beta_bar of eq. 3.29 if "
        "daha_dynamic); eq. 4.1 has 3", low=0.0, low_inclusive=False, high=MAX_DAHA_COEFFICIENT),
    _ts("daha_dynamic", bool, _DAHA.dynamic, "1", "damping and multiplier rate from eq. 3.29 (with a "
        "stability cap) instead of constants"),
    _ts("daha_overlap_tolerance", float, _DAHA.overlap_tolerance, LENGTH_UNITS, "eps_c of eq. 3.28 (eq. 4.1)",
        low=0.0, low_inclusive=False, high=LARGEST_QUANTITY),
    _ts("daha_steadiness_tolerance", float, _DAHA.steadiness_tolerance, LENGTH_UNITS,
        "eps_s of eq. 3.27 (eq. 4.1)", low=0.0, low_inclusive=False, high=LARGEST_QUANTITY),
    _ts("daha_max_overlap_tolerance", float, _DAHA.max_overlap_tolerance, LENGTH_UNITS,
        "bound on the deepest overlap sqrt(phi_ij) at convergence (ours; the mean of eq. 3.28 alone hides "
        "single deep overlaps)", low=0.0, low_inclusive=False, high=LARGEST_QUANTITY),
    _ts("daha_initial_multiplier", float, _DAHA.initial_multiplier, "1", "lambda of eq. 3.26", low=0.0,
        high=MAX_DAHA_COEFFICIENT),
    _ts("daha_carry_multipliers", bool, _DAHA.carry_multipliers, "1", "a link starts each minimisation from "
        "its multiplier at the end of the previous one (false: eq. 3.26 for every pair, 10x slower)"),
    _ts("daha_sleep_tolerance", float, _DAHA.sleep_tolerance, LENGTH_UNITS, "a sphere that moved at most this in "
        "a full DAHA sweep, and overlaps no partner by more than eps_c, is skipped until a partner moves "
        "(0: every sphere in every iteration)", low=0.0, high=LARGEST_QUANTITY),
    _ts("daha_max_iterations", int, _DAHA.max_iterations, "1", "DAHA iterations before a minimisation is "
        "reported as not converged", low=1),
)

STATISTICS = (
    Statistic("box_length", LENGTH_UNITS, "box length L"),
    Statistic("aspect_ratio", "1", "aspect ratio A_r of the final configuration (eq. 4.4)"),
    Statistic("orientation", "1", "orientation D, leading eigenvector of the gyration tensor (eq. 4.5)",
              dims=("component",)),
    Statistic("contact_number", "1", "relative average number of contacts per sphere N_c (eq. 4.6, self pairs included as printed)"),
    Statistic("pair_distribution", "1", "pair distribution P(r), mean number of spheres within r, itself included (eq. 4.7)",
              dims=("r",)),
    Statistic("box_count", "1", "number of boxes of side eps holding a sphere centre (eq. 4.8)", dims=("box_size",)),
    Statistic("fractal_dimension", "1", "box-counting fractal dimension D_f, fitted on 3R <= eps <= L/2 (eq. 4.8)"),
    Statistic("fractal_prefactor", "1", f"prefactor a of eq. 4.8 with eps in {LENGTH_UNITS}"),
    Statistic("structure_factor", "1", "static structure factor S(q) of the monomer centres, Debye's formula "
              "(sin(qr)/(qr) in 3-D, J0(qr) in 2-D; NaN unless compute_structure_factor = true)", dims=("q",)),
    Statistic("radius_of_gyration", LENGTH_UNITS, "radius of gyration of the final configuration, its monomers "
              "weighted by mass with their own second moments (r^2/2 for a disc, 3r^2/5 for a ball)"),
    Statistic("final_time", TIME_UNITS, "simulated time reached"),
    Statistic("n_clusters", "1", "number of clusters at the end", dtype="int64"),
    Statistic("n_events", "1", "number of events processed (ed) or time steps (ts)", dtype="int64"),
    Statistic("n_collisions", "1", "number of cluster merges", dtype="int64"),
    Statistic("n_wall_reflections", "1", "number of cluster reflections at the box walls", dtype="int64"),
    Statistic("n_minimisations", "1", "DAHA minimisations run (ts; 0 for ed)", dtype="int64"),
    Statistic("n_minimiser_iterations", "1", "DAHA iterations summed over the run (ts; 0 for ed)", dtype="int64"),
    Statistic("stop_reason", "1", "why the run stopped", dtype="int8", attrs=flag_attributes(STOP_REASONS)),
    # measured: it depends on how many ranks ran the task, not on the physics
    Statistic("rank_imbalance", "1", "largest over the time steps of max/mean work over the task's ranks "
              "(ts with --ranks-per-task > 1; 1 for ed and serial runs)", measured=True),
)


def box_length(params: dict) -> float:
    """L from the volume fraction (Table 1), or the unit lattice of supplementary A.  With lognormal
    radii the volume fraction is the expected one: the mean monomer volume is that of a monomer of
    radius R exp(d ln(sigma_g)^2 / 2), since E[r^d] = R^d exp(d^2 ln(sigma_g)^2 / 2)."""
    n, d = params["n_spheres"], params["dimension"]
    if params["initial_condition"] == SUPPLEMENTARY_INITIAL_CONDITION:
        return float(lattice_sites_per_side(n, d))  # spacing 1
    return box_length_for_volume_fraction(n, d, params["radius"] * _volume_radius_factor(params),
                                          params["volume_fraction"])


def _volume_radius_factor(params: dict) -> float:
    """(E[r^d])^(1/d) / R: 1 for equal radii, exp(d ln(sigma_g)^2 / 2) for lognormal ones."""
    if params.get("radius_distribution", "monodisperse") != "lognormal":
        return 1.0
    return math.exp(params["dimension"] * math.log(params["radius_geometric_std"]) ** 2 / 2.0)


def monomer_radii_and_masses(params: dict, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Each monomer's radius and mass: ``radius`` and ``mass`` for all, or lognormal radii ``R exp(ln(sigma_g)
    Z)`` (median R) with masses ``m (r / R)^d``.  Drawn after the positions and velocities, so that these do
    not depend on the radii; at sigma_g = 1 every radius is R and every mass m, exactly."""
    n, radius = params["n_spheres"], params["radius"]
    if params["radius_distribution"] != "lognormal":
        return np.full(n, radius), np.full(n, params["mass"])
    factors = np.exp(math.log(params["radius_geometric_std"]) * rng.standard_normal(n))
    return radius * factors, params["mass"] * factors ** params["dimension"]


def _check_lattice_fits(params: dict, length: float, largest_radius: float) -> None:
    """Condition 4.2 for the largest monomer drawn: the lattice spacing exceeds its diameter."""
    spacing = lattice_spacing(params["n_spheres"], params["dimension"], length)
    if spacing > 2.0 * largest_radius:
        return
    if largest_radius > params["radius"]:
        raise JobError(f"the initial lattice does not fit the largest radius drawn: spacing {spacing:.6g} must "
                       f"exceed its diameter {2 * largest_radius:.6g} (condition 4.2); lower volume_fraction, "
                       f"radius or radius_geometric_std (= {params['radius_geometric_std']:g})")
    raise JobError(f"the initial lattice does not fit in the box: spacing {spacing:.6g} must exceed the "
                   f"diameter 2R = {2 * params['radius']:.6g} (condition 4.2, L^d > (2R)^d N); "
                   "lower volume_fraction or radius")


def check(params: dict) -> None:
    """Cross-field checks of one parameter point; the lattice must fit (condition 4.2) and the
    box must hold the box sizes the fit of D_f needs."""
    initial = params["initial_condition"]
    if initial == PAPER_INITIAL_CONDITION and params["volume_fraction"] is None:
        raise JobError("volume_fraction is required with initial_condition = 'lattice_isotropic' "
                       "(it sets the box length, Table 1); allowed: 0 < volume_fraction < 1")
    if initial == SUPPLEMENTARY_INITIAL_CONDITION and params["volume_fraction"] is not None:
        raise JobError("volume_fraction must not be given with initial_condition = 'unit_lattice_uniform' "
                       "(the box length follows from the unit lattice spacing)")
    length = box_length(params)
    if not length <= LARGEST_QUANTITY:
        raise JobError(f"the box length L = {length:.6g} that radius = {params['radius']!r} and volume_fraction = "
                       f"{params['volume_fraction']!r} give for n_spheres = {params['n_spheres']} exceeds "
                       f"{LARGEST_QUANTITY:g}; allowed: a smaller radius or a larger volume_fraction")
    if not params["structure_factor_q_min"] < params["structure_factor_q_max"]:
        raise JobError(f"structure_factor_q_min = {params['structure_factor_q_min']!r} must be below "
                       f"structure_factor_q_max = {params['structure_factor_q_max']!r}")
    if params["radius_distribution"] != "lognormal" and params["radius_geometric_std"] != 1.0:
        raise JobError(f"radius_geometric_std = {params['radius_geometric_std']!r} needs radius_distribution = "
                       "'lognormal'; allowed with 'monodisperse': 1 (or leave it out)")
    _check_lattice_fits(params, length, params["radius"])
    _check_box_counting(params)


def _fits_fractal_dimension(params: dict) -> bool:
    """Whether the box-counting fit of D_f (:func:`cluster_statistics`) has the box sizes it needs."""
    return fit_box_sizes(box_length(params), params["radius"], params["box_levels"]) >= MIN_FIT_BOX_SIZES


def _check_box_counting(params: dict) -> None:
    if _fits_fractal_dimension(params):
        return
    remedy = ("lower volume_fraction" if params["initial_condition"] == PAPER_INITIAL_CONDITION
              else "lower radius")
    raise JobError(f"the box-counting fit of D_f needs at least two box sizes eps = L/2^m with 3R <= eps <= L/2; "
                   f"this point has L = {box_length(params):.6g}, R = {params['radius']:.6g} (it needs L >= 12R): "
                   f"raise n_spheres or {remedy}")


def coordinates(fixed: dict) -> dict[str, Coordinate]:
    components = COMPONENTS[: fixed["dimension"]]
    r_over_radius = pair_distribution_grid(1.0, fixed["pair_distribution_points"])
    levels = np.arange(1, fixed["box_levels"] + 1)
    return {
        "component": coded_coordinate("Cartesian component", components),
        "r": Coordinate(r_over_radius, "1", "pair distance r in units of the sphere radius R"),
        "box_size": Coordinate(2.0 ** -levels, "1", "box side relative to the box length, eps_m / L = 2^-m"),
        "q": Coordinate(structure_factor_grid(fixed), "1", "scattering wavenumber q in units of 1/R"),
    }


def structure_factor_grid(fixed: dict) -> np.ndarray:
    """The q R values of S(q): ``structure_factor_points`` log-spaced from q_min R to q_max R."""
    return np.geomspace(fixed["structure_factor_q_min"], fixed["structure_factor_q_max"],
                        fixed["structure_factor_points"])


def cost(params: dict) -> float:
    return float(params["n_spheres"]) ** 1.3


def memory(params: dict) -> int:
    """Peak memory of one task in bytes: ``BYTES_PER_SPHERE`` per sphere.

    Every array of a task grows linearly with N: the state of the spheres and clusters
    (positions, velocities, displacements, bounding boxes, cluster lists: about 25 arrays of
    N or N x d numbers), the neighbour lists (at least 8 int64 per sphere), the event queue
    (2N events and one per two neighbour pairs, 7 words each), the cell grids (at most 8 cells
    per sphere, several int64 arrays each) and the sorted copies of the statistics; TS adds its
    links, tiles and DAHA multipliers.  Measured peaks: 0.6-0.9 KiB per sphere in 2D and 3D,
    ED and TS, at volume fractions 0.1-0.3; 1.5 KiB in a dilute box (V_f = 0.005), where the
    cell grids reach their cap.
    """
    return BYTES_PER_SPHERE * params["n_spheres"]


def memory_keys(params: dict) -> tuple[str, ...]:
    return ("n_spheres",)


def warm_up_parameters(params: dict) -> dict:
    """The point with fewer spheres: the smallest full square or cube lattice of at least WARM_UP_SIDE^d
    spheres whose box holds the box sizes of the fit of D_f, or N if that is fewer.

    A full lattice of at most N spheres fits wherever N does (condition 4.2), and its box
    grows with its side, so the warm-up point passes :func:`check` when the point does.  It runs to
    one cluster whatever the point's ``max_time`` and ``max_events``, so that it meets collisions,
    minimisations and merges, and compiles their kernels, even for a task of a few time steps.
    """
    params = _barely_unequal(params)
    n, d = params["n_spheres"], params["dimension"]
    side = WARM_UP_SIDE[d]
    while side ** d < n and not _fits_fractal_dimension({**params, "n_spheres": side ** d}):
        side += 1
    until_one_cluster = {"max_time": math.inf, "max_events": next(p.default for p in PARAMETERS if p.name == "max_events")}
    return {**params, "n_spheres": min(n, side ** d), **until_one_cluster}


def _barely_unequal(params: dict) -> dict:
    """Lognormal radii barely unequal, in the box of the point's radii: the warm-up compiles the kernels of
    unequal radii, and its lattice, as wide as the point's, fits them whenever it fits the median radius (the
    point's own largest radius is checked when it is drawn)."""
    if params["radius_distribution"] != "lognormal":
        return params
    warm = {**params, "radius_geometric_std": WARM_UP_GEOMETRIC_STD}
    if params["volume_fraction"] is not None:  # the same box length: the volume fraction scales with E[r^d]
        warm["volume_fraction"] = params["volume_fraction"] * (
            _volume_radius_factor(warm) / _volume_radius_factor(params)) ** params["dimension"]
    return warm


@dataclass
class _Run:
    """What either method returns, in the solver's terms."""

    positions: np.ndarray
    velocities: np.ndarray
    cluster: np.ndarray
    links: np.ndarray
    time: float
    n_events: int
    n_collisions: int
    n_wall_reflections: int
    n_minimisations: int
    n_minimiser_iterations: int
    stop_reason: str
    imbalance: np.ndarray  #: max/mean work over the ranks per contact-searching time step (ts; empty for ed)


def daha_parameters(params: dict) -> DahaParameters:
    return DahaParameters(
        damping=params["daha_damping"], step=params["daha_step"], attraction=params["daha_attraction"],
        penalty=params["daha_penalty"], multiplier_rate=params["daha_multiplier_rate"],
        overlap_tolerance=params["daha_overlap_tolerance"],
        steadiness_tolerance=params["daha_steadiness_tolerance"],
        max_overlap_tolerance=params["daha_max_overlap_tolerance"],
        initial_multiplier=params["daha_initial_multiplier"], dynamic=params["daha_dynamic"],
        max_iterations=params["daha_max_iterations"], carry_multipliers=params["daha_carry_multipliers"],
        sleep_tolerance=params["daha_sleep_tolerance"])


def _domain(comm: "MPI.Comm", length: float, dimension: int, tiled: bool):
    """The tile decomposition of the box over ``comm``; None (serial) on one rank unless ``tiled``."""
    if comm.Get_size() == 1 and not tiled:
        return None
    from parsim.aggregation.tiled import DecomposedDomain  # here, so that `parsim validate` never initialises MPI

    return DecomposedDomain(comm, length, dimension)


def _run_ts(params, positions, velocities, radii, masses, length, comm: "MPI.Comm", tiled: bool) -> _Run:
    try:
        result = simulate_ts(positions, velocities, radii, masses, length,
                             time_step_factor=params["time_step_factor"], formulation=params["formulation"],
                             daha=daha_parameters(params),
                             attraction_range=params["attraction_range"] * params["radius"],
                             max_time=params["max_time"], max_steps=params["max_events"],
                             domain=_domain(comm, length, params["dimension"], tiled))
    except MinimiserFailure as failure:
        raise NumericalError(f"time stepping: {failure}") from None
    reason = "max_events" if result.stop_reason == "max_steps" else result.stop_reason
    return _Run(result.positions, result.velocities, result.cluster, result.links, result.time, result.n_steps,
                result.n_collisions, result.n_wall_reflections, result.n_minimisations, result.n_iterations,
                reason, result.imbalance)


def _run_ed(params, positions, velocities, radii, masses, length) -> _Run:
    result = simulate_ed(positions, velocities, radii, masses, length,
                         max_time=params["max_time"], max_events=params["max_events"])
    return _Run(result.positions, result.velocities, result.cluster, result.links, result.time,
                result.n_events, result.n_collisions, result.n_wall_reflections, 0, 0, result.stop_reason,
                np.ones(0))


def solve(params: dict, rng: np.random.Generator, comm: "MPI.Comm", tiled: bool = False) -> TaskResult | None:
    """One task on the ranks of ``comm``; the result is on its rank 0, the other ranks return None.
    ``tiled``: time stepping in tiles even on one rank, as on several (see :func:`rehearse_spread`)."""
    leader = comm.Get_rank() == 0
    if params["method"] == "ed" and not leader:
        return None  # ED is serial: the group's rank 0 computes it
    n, d, radius = params["n_spheres"], params["dimension"], params["radius"]
    length = box_length(params)
    with phase("initial_condition"):
        positions = lattice_positions(n, d, length, rng)
        if params["initial_condition"] == PAPER_INITIAL_CONDITION:
            velocities = isotropic_velocities(n, d, params["speed"], rng)
        else:
            velocities = uniform_cube_velocities(n, d, rng)
        radii, masses = monomer_radii_and_masses(params, rng)
        _check_lattice_fits(params, length, float(radii.max()))

    with phase("steps"):
        if params["method"] == "ts":
            run = _run_ts(params, positions, velocities, radii, masses, length, comm, tiled)
        else:
            run = _run_ed(params, positions, velocities, radii, masses, length)
    if not leader:
        return None
    if not (np.all(np.isfinite(run.positions)) and np.all(np.isfinite(run.velocities))):
        raise NumericalError(f"non-finite positions or velocities after {run.n_events} events")

    lower, upper = np.zeros(d), np.full(d, length)
    with phase("statistics"):
        shape = cluster_statistics(run.positions, radii, lower, upper,
                                   contact_factor=params["contact_factor"],
                                   r_values=pair_distribution_grid(radius, params["pair_distribution_points"]),
                                   box_levels=params["box_levels"], masses=masses)
        q_grid = structure_factor_grid(params)
        scattering = (structure_factor(run.positions, q_grid / radius) if params["compute_structure_factor"]
                      else np.full(q_grid.size, np.nan))
    statistics = {
        "box_length": length,
        **{name: shape[name] for name in ("aspect_ratio", "orientation", "contact_number", "pair_distribution",
                                          "box_count", "fractal_dimension", "fractal_prefactor",
                                          "radius_of_gyration")},
        "structure_factor": scattering,
        "final_time": run.time,
        "n_clusters": int(run.cluster.max()) + 1,
        "n_events": run.n_events,
        "n_collisions": run.n_collisions,
        "n_wall_reflections": run.n_wall_reflections,
        "n_minimisations": run.n_minimisations,
        "n_minimiser_iterations": run.n_minimiser_iterations,
        "stop_reason": STOP_REASONS.index(run.stop_reason),
        "rank_imbalance": float(run.imbalance.max(initial=1.0)),
    }
    configuration = Configuration(
        arrays={"spheres/position": run.positions, "spheres/radius": radii, "spheres/mass": masses,
                "spheres/velocity": run.velocities, "spheres/cluster": run.cluster, "links": run.links,
                "diagnostics/rank_imbalance": run.imbalance},
        box_lower=lower, box_upper=upper, periodic=np.zeros(d, dtype=bool))
    return TaskResult(statistics, configuration)


def rehearse_spread(params: dict) -> None:
    """Solve the small point ``params`` on this process alone as a task on several ranks is solved: time
    stepping in tiles (the kernels of tiles, ghosts and their pair lists, which a serial run never calls),
    event-driven as on one rank.  The warm-up of ``--ranks-per-task``: the kernels are the same for any
    number of ranks."""
    from mpi4py import MPI

    solve(params, np.random.default_rng(0), MPI.COMM_SELF, tiled=True)


def rare_kernels(params: dict) -> None:
    """Compile, or load, the time-stepping kernels that the warm-up's small point may not reach
    (:mod:`parsim.core.ts.rare`)."""
    if params["method"] == "ts":
        compile_rare_kernels(params["dimension"])


SOLVER = Solver(kind="aggregation", description="ballistic aggregation of hard spheres (Degond et al. 2024)",
                parameters=PARAMETERS, statistics=STATISTICS, coordinates=coordinates, check=check,
                cost=cost, memory=memory, memory_keys=memory_keys, warm_up_parameters=warm_up_parameters,
                solve=solve, decomposable=True, rehearse_spread=rehearse_spread,
                rare_kernels=rare_kernels)
