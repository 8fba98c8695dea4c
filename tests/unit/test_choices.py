"""Project choices of docs/model.md 'Assumptions and project choices' that no physics test covers otherwise."""

import numpy as np

from selfas_graph.model import events as ev
from selfas_graph.model.graph import classify_rods
from selfas_graph.model.params import ChargeDistribution, ExternalDipole
from selfas_graph.model.state import draw_charges
from selfas_graph.model.terms import external_monopoles


def test_direct_anode_cathode_contact_is_no_short_circuit():
    """B5: a contact joining a cathode-touching tip to an anode-touching tip, no rod between: no filament."""
    # rod 0's tip b (1) touches the cathode, rod 1's tip a (2) the anode, and tips 1 and 2 touch each other
    topo = classify_rods(2, np.array([[1, 2]]), np.array([1, 2]), np.array([ev.CONDUCTOR_CATHODE, ev.CONDUCTOR_ANODE]))
    assert topo.n_filament == 0 and not topo.has_short_circuit


def test_two_level_charges_give_exact_counts():
    """B15: two_level gives exactly round(high_fraction n) rods the high value, at random places."""
    dist = ChargeDistribution(distribution="two_level", low=1.0, high=2.0, high_fraction=1 / 3)
    q = draw_charges(dist, 600, np.random.default_rng(4))
    assert (q == 2.0).sum() == 200 and (q == 1.0).sum() == 400
    assert not np.array_equal(np.flatnonzero(q == 2.0), np.arange(200))  # not simply the first 200


def test_external_dipole_moment_points_along_plus_z():
    """B16: +Z_Mext sits at z = +L_ext/2, so the dipole's moment is along +z (co-directed with B_ext in Fig. 8)."""
    pos, q = external_monopoles(ExternalDipole(magnetic_charge=10.0, length=20.0))
    np.testing.assert_array_equal(pos, [[0, 0, 10.0], [0, 0, -10.0]])
    np.testing.assert_array_equal(q, [10.0, -10.0])
    moment = (q[:, None] * pos).sum(axis=0)
    assert moment[2] > 0
