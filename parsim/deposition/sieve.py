"""Particle size distributions given as a sieve curve (a grading curve).

File
----
Two columns, one sieve per line: the sieve size (aperture, a length in whatever unit the
caller uses; sizes are returned in that unit) and the cumulative percent passing it
(0-100), as a sieve analysis reports them (ISO 17892-4, ASTM D6913).  Accepted: a header
line (a first line without any number) or none; columns separated by commas, whitespace or
semicolons (with semicolons a decimal comma is accepted too, as spreadsheets write it in
many locales); blank lines and everything after ``#`` ignored; a UTF-8 byte order mark;
rows in any order (they are sorted by size).  The percentages are by mass (the usual
grading curve) or by number of particles: the caller says which (``basis``).

Required, else a :class:`JobError` naming the file and the line: at least two sieves;
sizes from 1e-30 to 1e30, each given once; percent passing in [0, 100] and never decreasing as
the size grows; exactly 100 % passing the largest sieve.

Conventions
-----------
* A sieve of size ``d`` passes the particles of size ``<= d``.
* Between neighbouring sieves the cumulative is linear in ln(size): the straight segments
  of a grading curve drawn on a logarithmic size axis, the way sieve analyses are plotted
  (ISO 17892-4, ASTM D6913) and D10, D60 read off them.  Within an interval the material
  (mass or number, per the basis) is thus uniform in ln(size).
* Fines: a fraction P0 > 0 passing the smallest sieve d0 (the pan) is spread the same way
  over [d0 / r, d0], with r = d1 / d0 the ratio of the two smallest sieves: the curve is
  continued one sieve step below d0, down to 0 %.  A sieve listed at 0 % sets the smallest
  size instead.
* Mass basis: mass is proportional to size**3 (particles of one shape and density; in
  parsim every particle is one template scaled), so the number density of sizes is
  f_n(d) ~ f_m(d) / d**3.  Within an interval [a, b] holding the mass fraction dP, the mass
  per ln d is dP / ln(b/a), so the interval's number weight is
  dP (a**-3 - b**-3) / (3 ln(b/a)) and the number cumulative of a size d inside it is
  (a**-3 - d**-3) / (a**-3 - b**-3), inverted in closed form.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parsim.errors import JobError

#: What the percent passing of a sieve curve counts.
BASES = ("mass", "number")
#: The sizes a sieve may have: their cubes (particle volumes) and inverse cubes stay within double precision.
SMALLEST_SIZE, LARGEST_SIZE = 1e-30, 1e30


@dataclass(frozen=True)
class SieveCurve:
    """Sieve sizes (ascending) and the fraction of the material passing each.

    The fractions are in [0, 1], non-decreasing, and 1 at the largest sieve.
    """

    sizes: tuple[float, ...]
    passing: tuple[float, ...]


def read_sieve_curve(path: str | Path) -> SieveCurve:
    """The sieve curve in the file ``path`` (format and checks in the module docstring)."""
    path = Path(path)
    sieves = sorted(_sieves(path), key=lambda sieve: sieve[1])
    _check_curve(path, sieves)
    return SieveCurve(tuple(size for _, size, _ in sieves), tuple(percent / 100.0 for _, _, percent in sieves))


def fraction_passing(curve: SieveCurve, sizes) -> np.ndarray:
    """The curve's cumulative at ``sizes``: 0 below the smallest size, 1 above the largest sieve."""
    sieves, passing = _completed(curve)
    return np.interp(np.log(sizes), np.log(sieves), passing, left=0.0, right=1.0)


def sample_sizes(curve: SieveCurve, basis: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` particle sizes (float64) drawn from ``curve`` read as a ``basis`` cumulative.

    Inverse-transform sampling of the number cumulative: one uniform number per size.
    """
    _check_basis(basis)
    lower, upper, fraction = _intervals(curve)
    cumulative = np.concatenate([[0.0], np.cumsum(_number_weights(lower, upper, fraction, basis))])
    cumulative /= cumulative[-1]
    u = rng.random(n)
    interval = np.searchsorted(cumulative[1:], u, side="right")  # cumulative[k] <= u < cumulative[k + 1]
    within = (u - cumulative[interval]) / (cumulative[interval + 1] - cumulative[interval])
    sizes = _quantile_in_interval(lower[interval], upper[interval], within, basis)
    return np.clip(sizes, lower[interval], upper[interval])  # no rounding past a sieve


def mean_cubed_size(curve: SieveCurve, basis: str) -> float:
    """The number-weighted mean of size**3 (a particle's volume is proportional to it)."""
    _check_basis(basis)
    lower, upper, fraction = _intervals(curve)
    if basis == "mass":  # E_n[d^3] = (integral of f_m) / (integral of f_m d^-3), the mass fractions sum to 1
        return float(1.0 / np.sum(_number_weights(lower, upper, fraction, basis)))
    log_ratio = np.log(upper / lower)
    return float(np.sum(fraction * lower**3 * np.expm1(3.0 * log_ratio) / (3.0 * log_ratio)))


def size_range(curve: SieveCurve) -> tuple[float, float]:
    """The smallest and the largest size the curve holds (no drawn size lies outside)."""
    lower, upper, fraction = _intervals(curve)
    holding = np.flatnonzero(fraction > 0.0)
    return float(lower[holding[0]]), float(upper[holding[-1]])


def _completed(curve: SieveCurve) -> tuple[np.ndarray, np.ndarray]:
    """Sizes and passing fractions starting at 0 %: fines get one sieve step below the smallest sieve."""
    sizes, passing = np.array(curve.sizes), np.array(curve.passing)
    if passing[0] > 0.0:
        sizes = np.concatenate([[sizes[0] ** 2 / sizes[1]], sizes])
        passing = np.concatenate([[0.0], passing])
    return sizes, passing


def _intervals(curve: SieveCurve) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower size, upper size and fraction of the material of each interval between sieves."""
    sizes, passing = _completed(curve)
    return sizes[:-1], sizes[1:], np.diff(passing)


def _number_weights(lower, upper, fraction, basis) -> np.ndarray:
    """Each interval's share of the particles (unnormalised)."""
    if basis == "number":
        return fraction
    log_ratio = np.log(upper / lower)  # mass per ln d is fraction / log_ratio, number per ln d that times d^-3
    return fraction * lower**-3.0 * -np.expm1(-3.0 * log_ratio) / (3.0 * log_ratio)


def _quantile_in_interval(lower, upper, within, basis) -> np.ndarray:
    """The size at which the number cumulative inside [lower, upper] reaches ``within`` (in [0, 1])."""
    log_ratio = np.log(upper / lower)
    if basis == "number":  # log-uniform
        return lower * np.exp(within * log_ratio)
    return lower * (1.0 + within * np.expm1(-3.0 * log_ratio)) ** (-1.0 / 3.0)  # number density ~ d^-4


def _check_basis(basis: str) -> None:
    if basis not in BASES:
        raise JobError(f"sieve curve basis = {basis!r}: allowed: {', '.join(map(repr, BASES))}")


def _sieves(path: Path) -> list[tuple[int, float, float]]:
    """(line number, size, percent passing) of each sieve, in file order, each checked alone."""
    lines = _content_lines(path)
    if lines and not any(map(_is_number, lines[0][1])):
        lines = lines[1:]  # the header
    return [(number, *_sieve(path, number, cells)) for number, cells in lines]


def _content_lines(path: Path) -> list[tuple[int, list[str]]]:
    """(line number, cells) of every line that is not blank or a comment."""
    if not path.is_file():
        raise _invalid(path, "no such file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise _invalid(path, "not a text file (not UTF-8)") from None
    lines = []
    for number, line in enumerate(text.splitlines(), start=1):
        content = line.split("#", 1)[0].strip()
        if content:
            lines.append((number, _cells(content)))
    return lines


def _cells(content: str) -> list[str]:
    if ";" in content:  # a comma is then a decimal comma
        return [cell.strip().replace(",", ".") for cell in content.split(";")]
    if "," in content:
        return [cell.strip() for cell in content.split(",")]
    return content.split()


def _sieve(path: Path, number: int, cells: list[str]) -> tuple[float, float]:
    if len(cells) != 2 or not all(map(_is_number, cells)):
        raise _invalid(path, f"line {number} holds {cells}; allowed: two numbers, sieve size and percent passing")
    size, percent = float(cells[0]), float(cells[1])
    if not SMALLEST_SIZE <= size <= LARGEST_SIZE:
        raise _invalid(path, f"line {number}: sieve size {cells[0]}; allowed: a size from {SMALLEST_SIZE:g} to "
                             f"{LARGEST_SIZE:g}")
    if not 0.0 <= percent <= 100.0:
        raise _invalid(path, f"line {number}: {cells[1]} % passing; allowed: 0 to 100")
    return size, percent


def _check_curve(path: Path, sieves: list[tuple[int, float, float]]) -> None:
    """Checks of the sieves together, sorted by size."""
    if len(sieves) < 2:
        where = f" (line {sieves[0][0]})" if sieves else ""
        raise _invalid(path, f"found {len(sieves)} sieve(s){where}; "
                             "allowed: at least 2 lines of sieve size, percent passing")
    for (line_a, size_a, percent_a), (line_b, size_b, percent_b) in zip(sieves, sieves[1:]):
        if size_b == size_a:
            first, second = sorted((line_a, line_b))
            raise _invalid(path, f"lines {first} and {second} both give the sieve size {size_a:g}; "
                                 "allowed: each size once")
        if percent_b < percent_a:
            raise _invalid(path, f"line {line_b}: {percent_b:g} % passing the sieve {size_b:g} is less than "
                                 f"{percent_a:g} % passing the smaller sieve {size_a:g} (line {line_a}); allowed: "
                                 "a percent passing that never decreases as the sieve size grows")
    line, size, percent = sieves[-1]
    if percent != 100.0:
        raise _invalid(path, f"line {line}: {percent:g} % passing the largest sieve {size:g}; allowed: 100 % "
                             "(all the material passes the largest sieve: add a sieve that passes 100 %)")


def _invalid(path: Path, reason: str) -> JobError:
    return JobError(f"sieve curve {str(path)!r}: {reason}")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
