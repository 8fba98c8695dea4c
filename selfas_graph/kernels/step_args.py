"""The arguments of a run of compiled fast steps (``steps.py``), by name.

numba passes a named tuple to a compiled function as it passes a tuple (each field typed on its own), and a
compiled function reads its fields by name (``args.x``): the caller (``model/compiled.py``) builds
:class:`FastStepArgs` by keyword, and the call's control flow (``steps.py``) and the task loop
(``step_tasks.py::run_tasks``) read what they need by name; the two arrays of numbers, ``scalars`` and
``limits``, are read by the named positions below.

The work of a task (``step_tasks.py::forces``, ``split_brakes``) takes its arrays one by one: a compiled
function that takes the named tuple counts a reference to each of its arrays on entry and on return, and
taking all of them in ``forces`` and ``split_brakes`` made a late Fig. 2 fast step 2-3 % slower (117-120
against 115-117 us on one thread, Zen 5).
"""

from collections import namedtuple

#: the positions of ``FastStepArgs.scalars`` (``model/compiled.py::CompiledSteps`` fills them by these names;
#: numba takes the names as constants): the ambient brake's coefficient, r*, the tip stiffness kappa, the tip
#: brake's coefficient when explicit (NaN: split or off) and when split (0: explicit or off), the cathode's and
#: the anode's z, the electrode walls' explicit and split brake coefficients, the external filament's current and
#: wire radius, the dipole monopoles' explicit and split brake coefficients, the fast range of the tip-tip
#: force (inner, outer), half the tip list's skin squared, and the contacts' release radius
(
    SC_AMBIENT_K,
    SC_RSTAR,
    SC_KAPPA,
    SC_TIP_BRAKE_K,
    SC_TIP_BRAKE_SPLIT,
    SC_CATHODE_Z,
    SC_ANODE_Z,
    SC_WALL_K,
    SC_WALL_SPLIT,
    SC_FILAMENT_CURRENT,
    SC_FILAMENT_W,
    SC_POLE_K,
    SC_POLE_SPLIT,
    SC_FAST_INNER,
    SC_FAST_OUTER,
    SC_HALF_SKIN2,
    SC_RELEASE,
) = range(17)
N_SCALARS = 17
#: the positions of ``FastStepArgs.limits``: the network on (1.0) or off, the contact test's electrode planes
#: and filament surface radius (NaN: none), the height tolerance, the health limits BOND_BREAK and
#: MAX_STEP_DISPLACEMENT, the largest bond error so far
LIM_NETWORK, LIM_CATHODE_Z, LIM_ANODE_Z, LIM_FILAMENT_R, LIM_HEIGHT_TOL, LIM_BOND_BREAK, LIM_MAX_MOVE, LIM_MAX_BOND = (
    range(8)
)
N_LIMITS = 8

FastStepArgs = namedtuple(
    "FastStepArgs",
    [
        "x",
        "v",
        "hist_v",
        "hist_a",
        "hist_p",
        "head",
        "slot_table",
        "step",
        "n_max",
        "slow_every",
        "dt",
        "length",
        "exact_bond",
        "project",
        "correct_velocity",
        "block",
        "total",
        "powered",
        "channel",
        "tip_charge",
        "rod_charge",
        "scalars",
        "plasma",
        "decay_walls",
        "decay_poles",
        "source",
        "source_charge",
        "line",
        "nodes",
        "weights",
        "held",
        "tip_far",
        "tip_fast",
        "rate",
        "base",
        "base_step",
        "extrapolate",
        "lists",
        "start",
        "index",
        "reference",
        "pairs",
        "on_cathode",
        "on_anode",
        "on_filament",
        "filament_tip",
        "filament_z",
        "centre",
        "centre_force",
        "before",
        "after",
        "save_x",
        "save_v",
        "bond_before",
        "power_log",
        "brake_work",
        "brake_hit",
        "limits",
        "phase_time",
    ],
)
FastStepArgs.__doc__ = """The state, parameters and scratch of a run of fast steps (``steps.py::fast_steps``).

x, v : (n_tips, 3) float64
    Positions and velocities, advanced in place.
hist_v, hist_a : (4, n_tips, 3) float64; hist_p : (4, n_power) float64
    The integrator's ring buffers; ``head`` the slot of the last step's derivatives; ``slot_table``
    (4, 4) int64, row h: the slots of f_n, ..., f_{n-3} when f_n is in slot h.
step, n_max, slow_every : int
dt : float
length : (n_rods,) float64 or empty; exact_bond, project, correct_velocity : bool
    As ``AdamsBashforth4`` takes them.
block : (n_channels, n_tips, 3) float64
    The force field's channel buffers; ``total`` (n_tips, 3) their sum; ``powered`` the
    non-conservative channels' rows.
channel : (len(steps.CHANNELS),) int64
    Each channel's row in ``block``, -1 for a channel that is off (or, for the line charge, slow:
    then it is one of the held forces).
tip_charge : (n_tips,) float64; rod_charge : (n_rods,) float64
scalars : (17,) float64
    ambient brake coefficient; tip law r*, kappa; tip brake coefficient (explicit; NaN: split);
    split tip brake coefficient (0: none); electrode planes z_c, z_a, explicit electrode
    brake; split electrode brake (0: none); filament current and radius; monopole brake
    (explicit); split monopole brake (0: none); fast range r_in, r_out; the tip list's
    (skin / 2)^2; contact release radius.
plasma : (4,) float64 or empty
    Axis x, y, radius and current of the plasma filament.
decay_walls, decay_poles : (3,) float64
    The split brakes' decay per planes or poles touched.
source, source_charge : (2, 3), (2,) float64
    The external dipole's monopoles (empty without).
line : (5,) float64; nodes, weights : float64
    The line charge's ends, density, screening length and radius; its quadrature (empty without).
held : (n_held,) int64
    Each held slow force's row in ``block``, -1 for ``tip_far`` (the tip-tip force less its fast part).
tip_far, tip_fast : (n_tips, 3) float64 (empty rows without the tip-tip term)
rate, base : (n_held, n_tips, 3) float64; base_step : (n_held,) int64, -1: held, not extrapolated
extrapolate : bool
lists : (3,) bool
    Where the Python step asks the tip list for an update: in the evaluation (tip-tip fast part,
    explicit tip brake), in the split tip brake, in the contact test.
start, index, reference : the tip list and the positions of its build
pairs, on_cathode, on_anode, on_filament : the contacts as the contact test reads them
    (``ContactSet.search_arrays``)
filament_tip, filament_z : the case (ii) filament contacts and their heights at the last solve
centre, centre_force : (n_rods, 3) float64 scratch (the line charge's rod centres and forces)
before, after, save_x, save_v : (n_tips, 3) float64 scratch
bond_before : (n_max,) float64; power_log : (n_max, n_power); brake_work : (n_max, 3) float64;
brake_hit : (n_max, 3) bool
    Per step: the bond error before the constraint, the channels' power, the split brakes' work
    and whether each brake acted (the logs the caller replays).
limits : (8,) float64
    network on (1.0) or off, electrode planes for the contact test (NaN: none), filament surface
    radius (NaN: none), height tolerance, health limits BOND_BREAK and MAX_STEP_DISPLACEMENT,
    the largest bond error so far.
phase_time : (9,) float64 or empty
    Empty: no timing. Otherwise, added to: the ticks of the cycle counter (``team.py::ticks``) of the
    whole call at [0] and of each phase at [kind] (``step_tasks.DUE`` ... ``CONTACTS``), as the leading
    thread sees them (from opening a phase to its last task done).
"""

Scratch = namedtuple("Scratch", ["ctl", "partial", "counts", "zero", "pair_k", "pair_l", "chunks"])
Scratch.__doc__ = """What a call of fast steps adds to its arguments (``steps.py::_prepare``).

ctl : (n,) int64 array
    The control block of the call's threads (``team.py``).
partial : (chunks, 6) float64; counts : (chunks, 4) int64
    Each block's results: maxima (columns ``step_tasks.P_*``) and the split brake's pairs and the contact
    test's counts.
zero : (n_held,) bool
    The held forces whose rate and base are +0 throughout the call (written on its first step only).
pair_k, pair_l : int64 arrays
    The close tip pairs the blocks found for the split tip brake, each block's from its first tip's row
    start.
chunks : int
    The blocks of rods.
"""
