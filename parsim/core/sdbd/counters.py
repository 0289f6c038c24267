"""Where a deposition spends its time: counters of the engine's work, off unless asked for.

``deposit_with_diagnostics(..., count=True)`` hands the kernel an array of ``N_COUNTERS``
int64 slots; without it the array is empty and every count is one untaken branch.  The
counts are machine-independent (steps, moves, candidate spheres tested, grid queries); the
times are processor cycles read with LLVM's ``readcyclecounter`` (the time-stamp counter on
x86, the virtual counter on ARM), summed per phase of a step:

* ``DECIDE``: the contacts' geometry and the steepest-descent decision (:mod:`.decision`);
* ``FALL``: a fall, its search of the columns below included (:mod:`.fall`);
* ``ROLL``: a rotation up to its earliest event (:mod:`.rolling`), of which ``CONTACT_SEARCH``
  is the search for new contacts with the sediment, ``GRID`` the grid queries in it, and
  ``TRIAL`` the decision after the trial rotation of 4.1 (:mod:`.frustration`);
* ``AFTER_MOVE``: the contacts kept after a move, the cycling test and the closing of near
  obstacles at rest (:mod:`.contacts`, :mod:`.cycling`);
* ``PARTICLE``: dropping a particle and freezing it into the sediment and its grid;
* ``TOTAL``: the whole run, so that the phases' shares can be read off and cycles turned into
  seconds by the run's wall-clock time.
"""

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from parsim.core.jit import jit

# counts
STEPS = 0  # decide-and-move steps
FALLS = 1
ROLLS = 2
FALL_CANDIDATES = 3  # sediment spheres tested by the search of a fall
ROLL_CANDIDATES = 4  # sediment spheres tested by the contact search of a rotation
GRID_QUERIES = 5  # grid_collect calls of the contact search of a rotation
ROLL_ENTRIES = 6  # candidates of a rotation whose circle meets the sphere: the entry angle is solved
TRIAL_DECISIONS = 7  # decisions after the trial rotation of 4.1
# cycles
DECIDE = 8
FALL = 9
ROLL = 10
CONTACT_SEARCH = 11
GRID = 12
TRIAL = 13
AFTER_MOVE = 14
PARTICLE = 15
TOTAL = 16
N_COUNTERS = 17

NAMES = ("steps", "falls", "rolls", "fall_candidates", "roll_candidates", "grid_queries", "roll_entries",
         "trial_decisions", "decide_cycles", "fall_cycles", "roll_cycles", "contact_search_cycles", "grid_cycles",
         "trial_cycles", "after_move_cycles", "particle_cycles", "total_cycles")


@intrinsic
def _read_cycle_counter(typingctx):
    """The processor's cycle counter (``llvm.readcyclecounter``; 0 where the target has none)."""
    def codegen(context, builder, signature, args):
        counter = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(64), []),
                                                 "llvm.readcyclecounter")
        return builder.call(counter, [])

    return types.int64(), codegen


@jit(inline="always")
def start(counters):
    """The cycle counter when counting, else 0 (nothing read)."""
    if counters.shape[0] == 0:
        return 0
    return _read_cycle_counter()


@jit(inline="always")
def stop(counters, slot, started):
    """Add the cycles since ``started`` (:func:`start`) to ``slot`` when counting."""
    if counters.shape[0] != 0:
        counters[slot] += _read_cycle_counter() - started


@jit(inline="always")
def add(counters, slot, amount):
    """Add ``amount`` to ``slot`` when counting."""
    if counters.shape[0] != 0:
        counters[slot] += amount
