"""The names inside selfas-graph's files: every dataset path and group name of a run file and a checkpoint.

Written once here, read by the writers and readers (``io/run_writer.py``, ``io/run_reader.py``,
``io/checkpoint.py``) and by everything else that opens a file (``io/export.py``, the CLI,
``ensemble/``). Event kinds are ``selfas_graph.model.events`` (``EventKind``), rod roles
``selfas_graph.model.topology`` (``FILAMENT``, ``ROLE_NAMES``); the file stores their numbers.

Run file (H5MD 1.1, https://www.nongnu.org/h5md/h5md.html)::

    /h5md                       attrs version=[1, 1]; groups author, creator (fixed-length strings)
    /h5md/modules/units         attrs version=[1, 0], system="reduced" (docs/model.md 'Reduced units')
    /particles/tips/box         attrs dimension=3, boundary=[none, none, none]
    /particles/tips/position    step (n,), time (n,), value (n, n_tips, 3)
    /particles/tips/velocity    step, time, value (if output.velocities)
    /particles/tips/charge      (n_tips,) magnetic charge (time-independent)
    /particles/tips/rod         (n_tips,) rod index of each tip (tip k belongs to rod k // 2)
    /particles/rods/box         as the tips' box (H5MD: every particles group holds one)
    /particles/rods/charge      (n_rods,) electric charge Z_i
    /particles/rods/length      (n_rods,) rod lengths, if the scene sets them
    /particles/rods/resistance  (n_rods,) rod resistances, if the scene sets them
    /connectivity/rods          (n_rods, 2) the two tips of each rod; attr particles_group -> /particles/tips
    /observables/<name>         step, time, value: one row per saved frame
    /observables/dt             step, time, value: simulated time between saved frames
    /observables/bond_error_per_step   step, value: the largest bond error of every step
    /parameters/selfas_graph    attrs: the run's provenance and status (io/run_provenance.py)
    /events                     (n_events,) records (step, time, kind, a, b); attrs kind_names, conductor_names
    /circuit_log                the current through the gap at each SHORT_CIRCUIT / OPEN_CIRCUIT (if contacts
                                are on; model/circuitlog.py), one row each, written with the events:
        step, time, kind            (n,) of the event; attr kind_names on kind
        total_current               (n,) the solve's total current (units J0), 0 at an OPEN_CIRCUIT
        rods_in_series              (n,) rods carrying the whole current, 0 at an OPEN_CIRCUIT
        filament_rods               (n,) rods in current-carrying filaments, 0 at an OPEN_CIRCUIT
    /graph                      the connectivity graph at every saved frame (if contacts are on):
        step, time                  (n_frames,)
        tip_contacts                (sum m_f, 2) tip pairs in contact; tip_contacts_count (n_frames,)
        conductor_tip, conductor_id, conductor_potential
                                    (sum k_f,) tip-conductor contacts; conductor_contacts_count (n_frames,)
        role                        (n_frames, n_rods) int8: model.topology.ROLE_NAMES
        current                     (n_frames, n_rods) rod currents J_i (units J0)
        potential                   (n_frames, n_tips) tip potentials (units R0 J0), 0 if floating
        floating                    (n_frames, n_tips) int8: 1 for a tip on no path between conductors
        attrs conductor_ids, conductor_potentials, conductor_per_contact, role_names

Checkpoint (io/checkpoint.py)::

    /snapshot                   Simulation.snapshot(): arrays as datasets, scalars as attributes
    /meta                       attrs: scenario text and overrides, run_id, run_name, t_end, version
    /failed                     a failure file's second state (the one that failed the checks)
"""

from __future__ import annotations

# ----------------------------------------------------------------------------- run file
H5MD = "h5md"
H5MD_AUTHOR = "author"
H5MD_CREATOR = "creator"
H5MD_UNITS = "modules/units"  #: inside H5MD

PARTICLES = "particles"
TIPS = "tips"  #: inside PARTICLES
RODS = "rods"  #: inside PARTICLES and CONNECTIVITY
BOX = "box"  #: inside every particles group

#: the three datasets of a time-dependent H5MD element (an observable, the positions)
STEP, TIME, VALUE = "step", "time", "value"

TIP_POSITION = "particles/tips/position"
TIP_POSITION_STEP = f"{TIP_POSITION}/{STEP}"
TIP_POSITION_TIME = f"{TIP_POSITION}/{TIME}"
TIP_POSITION_VALUE = f"{TIP_POSITION}/{VALUE}"
TIP_VELOCITY = "particles/tips/velocity"
TIP_VELOCITY_VALUE = f"{TIP_VELOCITY}/{VALUE}"
#: the time-dependent elements of the tips, by their H5MD name
TIP_ELEMENTS = {"position": TIP_POSITION, "velocity": TIP_VELOCITY}
TIP_CHARGE = "particles/tips/charge"
TIP_ROD = "rod"  #: inside TIPS

ROD_CHARGE = "particles/rods/charge"
ROD_LENGTH = "particles/rods/length"
ROD_RESISTANCE = "particles/rods/resistance"

CONNECTIVITY = "connectivity"
CONNECTIVITY_RODS = "connectivity/rods"

OBSERVABLES = "observables"
BOND_ERROR_PER_STEP = "bond_error_per_step"  #: inside OBSERVABLES: per step, without time
FRAME_INTERVAL = "dt"  #: inside OBSERVABLES
TOTAL_CURRENT = "total_current"  #: inside OBSERVABLES


def observable(name: str) -> str:
    """The group of an observable (``energy/kinetic`` -> ``observables/energy/kinetic``)."""
    return f"{OBSERVABLES}/{name}"


PROVENANCE = "parameters/selfas_graph"

EVENTS = "events"

CIRCUIT_LOG = "circuit_log"
#: the column datasets of CIRCUIT_LOG, the fields of model.circuitlog.CIRCUIT_LOG_DTYPE
CIRCUIT_LOG_COLUMNS = ("step", "time", "kind", "total_current", "rods_in_series", "filament_rods")

GRAPH = "graph"
#: datasets of GRAPH with one row per saved frame (``floating`` only in files from 0.4 on)
GRAPH_PER_FRAME = ("step", "time", "tip_contacts_count", "conductor_contacts_count", "role", "current", "potential")
GRAPH_FLOATING = "floating"
#: datasets of GRAPH with one row per tip-conductor contact
GRAPH_CONDUCTOR_CONTACTS = ("conductor_tip", "conductor_id", "conductor_potential")
#: the datasets a readable GRAPH holds
GRAPH_DATASETS = (
    "step",
    "time",
    "tip_contacts",
    "tip_contacts_count",
    "conductor_tip",
    "conductor_id",
    "conductor_potential",
    "conductor_contacts_count",
    "role",
    "current",
    "potential",
)
GRAPH_STEP = f"{GRAPH}/step"
GRAPH_TIME = f"{GRAPH}/time"


def graph(name: str) -> str:
    """The path of one dataset of GRAPH (``role`` -> ``graph/role``)."""
    return f"{GRAPH}/{name}"


# ----------------------------------------------------------------------------- checkpoint
CHECKPOINT_SNAPSHOT = "snapshot"
CHECKPOINT_META = "meta"
#: a failure file's group of the failed state (beside the last good one in CHECKPOINT_SNAPSHOT)
CHECKPOINT_FAILED = "failed"
