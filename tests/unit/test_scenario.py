"""Scenario validation: every rule gives a message naming the key and what is valid."""

import re
from pathlib import Path

import pytest

from selfas_graph.io.scenario import ScenarioError, load_scenario, scenario_from_text
from selfas_graph.model.simulation import Simulation

SCENARIOS = sorted((Path(__file__).parents[2] / "scenarios").glob("*.toml"))
GOOD = """
[rods]
count = 10
[placement]
box = [[-3, 3], [-3, 3], [-3, 3]]
[forces.tip_magnetic]
[forces.electrodes]
gap = 6.0
"""


def problems(text, overrides=()):
    with pytest.raises(ScenarioError) as info:
        scenario_from_text(text, overrides=overrides)
    return "\n".join(info.value.problems)


def test_good_scenario_resolves_defaults():
    p = scenario_from_text(GOOD).params
    assert p.rods.count == 10 and p.rods.rstar == 0.06 and p.integrator.dt == 1e-3
    assert p.forces.active() == ["tip_magnetic", "electrodes"]
    assert p.forces.yukawa is None  # a term not listed is off


def test_unknown_key_suggests_the_close_one():
    msg = problems(GOOD + "[forces.yukwa]\n")
    assert "forces.yukwa: unknown key; did you mean 'yukawa'?" in msg
    msg = problems(GOOD.replace("count = 10", "cuont = 10"))
    assert "rods.cuont: unknown key; did you mean 'count'?" in msg
    assert "valid keys here:" in msg


def test_wrong_type_names_key_and_expected_type():
    assert "rods.count: expected an integer, got '10' (str)" in problems(GOOD.replace("count = 10", 'count = "10"'))
    assert "integrator.dt: expected a number, got true (bool)" in problems(GOOD + "[integrator]\ndt = true\n")
    assert "integrator.position_projection: expected true or false" in problems(
        GOOD + "[integrator]\nposition_projection = 1\n"
    )
    assert "forces.uniform_field.B: expected an array of 3 numbers" in problems(
        GOOD + "[forces.uniform_field]\nB = [1, 2]\n"
    )


@pytest.mark.parametrize(
    "line, key, valid",
    [
        ("[integrator]\ndt = 0.0", "integrator.dt", "> 0"),
        ("[integrator]\ndt = -1e-3", "integrator.dt", "> 0"),
        ("[run]\nt_end = 0", "run.t_end", "> 0"),
        ("[rods.magnetic_charge]\nhigh_fraction = 1.5", "rods.magnetic_charge.high_fraction", "<= 1"),
        ("[forces.yukawa]\ntolerance = 0", "forces.yukawa.tolerance", "> 0"),
        # above 1 the energy check never stopped a run: 99 % off still "finished"
        ("[integrator]\nenergy_tolerance = 1e30", "integrator.energy_tolerance", "> 0 and <= 1"),
    ],
)
def test_out_of_range(line, key, valid):
    msg = problems(GOOD + line + "\n")
    assert f"{key}: " in msg and "out of range" in msg and valid in msg


def test_zero_rods_is_an_error():
    """A scene without rods has nothing to simulate: a clear error, not a crash in the writer."""
    assert "rods.count: 0 is out of range; valid: >= 1" in problems(GOOD.replace("count = 10", "count = 0"))


def test_rstar_at_or_above_half_rod_length():
    msg = problems(GOOD.replace("count = 10", "count = 10\ntransition_radius = 0.5"))
    assert "rods.transition_radius: 0.5 is out of range; valid: > 0 and < 0.5" in msg


def test_choice_with_suggestion():
    msg = problems(GOOD + '[integrator]\nbond_force = "exakt"\n')
    assert "integrator.bond_force: 'exakt' is not valid (did you mean 'exact'?); valid: exact, paper" in msg


def test_nan_and_inf_rejected():
    assert "integrator.dt: expected a finite number, got nan" in problems(GOOD + "[integrator]\ndt = nan\n")
    assert "every entry must be a finite number" in problems(GOOD + "[forces.uniform_field]\nB = [0, 0, inf]\n")


def test_rods_that_cannot_fit_the_box():
    msg = problems(GOOD.replace("count = 10", "count = 5000"))
    assert "rods.count: 5000 rods cannot fit the box" in msg
    msg = problems(GOOD.replace("[[-3, 3], [-3, 3], [-3, 3]]", "[[0, 0.5], [0, 0.5], [0, 0.5]]"))
    assert "a rod of length 1 cannot fit in a box" in msg


def test_box_beyond_electrodes_and_empty_range():
    assert "reaches beyond the electrodes at z = +-2" in problems(GOOD.replace("gap = 6.0", "gap = 4.0"))
    assert "the x range [3, -3] is empty" in problems(GOOD.replace("[[-3, 3], [-3", "[[3, -3], [-3"))


def test_circuit_needs_contacts_and_a_conductor():
    assert "with contacts.enabled = false it can never close" in problems(
        GOOD + "[circuit]\ndelta_J0 = 1.0\n[contacts]\nenabled = false\n"
    )
    assert "the circuit needs a conductor" in problems(
        GOOD.replace("[forces.electrodes]\ngap = 6.0\n", "").replace("[-3, 3]]", "[-3, 3]]") + "[circuit]\n"
    )
    assert "rod currents come from the circuit solve" in problems(GOOD + "[forces.current_field]\n")


def test_output_interval_shorter_than_dt():
    msg = problems(GOOD + "[integrator]\ndt = 0.01\n[output]\ninterval = 0.001\n")
    assert "output.interval = 0.001 is shorter than integrator.dt = 0.01" in msg


def test_all_problems_reported_together():
    msg = problems(GOOD.replace("count = 10", "count = -1") + "[integrator]\ndt = -1\n")
    assert "rods.count" in msg and "integrator.dt" in msg


def test_not_toml_and_missing_file(tmp_path, monkeypatch):
    assert "not valid TOML" in problems("[rods\ncount = ")
    with pytest.raises(ScenarioError, match="file not found") as absolute:
        load_scenario(tmp_path / "nope.toml")
    assert "working directory" not in str(absolute.value)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ScenarioError, match=re.escape(f"a relative path, read from the working directory {tmp_path}")):
        load_scenario("scenarios/nope.toml")  # a studies file's or a script's path, run from elsewhere
    junk = tmp_path / "junk.toml"
    junk.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(ScenarioError, match="not a UTF-8 text file"):
        load_scenario(junk)


def test_overrides_go_through_the_same_checks():
    sc = scenario_from_text(
        GOOD, overrides=["integrator.dt=5e-4", "forces.uniform_field.B=[0, 0, 1]", "integrator.bond_force=paper"]
    )
    assert sc.params.integrator.dt == 5e-4 and sc.params.forces.uniform_field.B == (0.0, 0.0, 1.0)
    assert sc.params.integrator.bond_force == "paper"
    assert "integrator.dt: -1.0 is out of range" in problems(GOOD, ["integrator.dt=-1"])
    # t_end > 0 but below half a step took no step at all
    assert "run.t_end = 1e-09 is shorter than integrator.dt" in problems(GOOD, ["run.t_end=1e-9"])
    assert "integrator.dtt: unknown key; did you mean 'dt'?" in problems(GOOD, ["integrator.dtt=1"])
    assert "expected key=value" in problems(GOOD, ["integrator.dt"])
    # a term is switched off by an override
    assert scenario_from_text(GOOD, overrides=["forces.electrodes=false"]).params.forces.electrodes is None
    # and a key of a term that is off switches it on again, whether the term was off in the file or by
    # an earlier override (docs/scenarios.md): "forces.yukawa is a value, not a table" before
    off_in_file = GOOD.replace("[forces.tip_magnetic]", "[forces]\nyukawa = false\n[forces.tip_magnetic]", 1)
    assert scenario_from_text(off_in_file).params.forces.yukawa is None
    for text, first in ((off_in_file, []), (GOOD, ["forces.yukawa=false"])):
        sc = scenario_from_text(text, overrides=[*first, "forces.yukawa.tolerance=1e-6"])
        assert sc.params.forces.yukawa.tolerance == 1e-6


def test_true_switches_an_absent_term_on_and_keeps_one_already_on():
    """`--set forces.TERM=true` (and `--grid forces.TERM=true,false`) on a term the scenario has replaced
    its table by the defaults without a word (Fig. 8's B_z 1.5 became 0.5); it is no change now. On a
    term that is off it switches it on with its defaults, from the command line and from Python."""
    fig8 = load_scenario(SCENARIOS[0].parent / "fig8_quick.toml")
    assert fig8.params.forces.uniform_field.B == (0.0, 0.0, 1.5)
    on = scenario_from_text(fig8.text, overrides=["forces.uniform_field=true"]).params
    assert on.forces.uniform_field == fig8.params.forces.uniform_field
    assert fig8.params.replace({"forces.uniform_field": True}) == fig8.params
    off = fig8.params.replace({"forces.uniform_field": False})
    assert off.forces.uniform_field is None
    assert off.replace({"forces.uniform_field": True}).forces.uniform_field.B == (0.0, 0.0, 0.5)  # the default
    sc = scenario_from_text(fig8.text, overrides=["forces.uniform_field=false", "forces.uniform_field=true"])
    assert sc.params.forces.uniform_field.B == (0.0, 0.0, 0.5)


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.name)
def test_every_shipped_scenario_loads_and_runs_a_few_steps(path):
    """Each file in scenarios/ validates, places its rods and takes steps without failure."""
    sc = load_scenario(path)
    sim = Simulation.from_scenario(sc)
    sim.step(5)
    # the projection leaves the round-off of a length of order 1: measured 8.9e-16 (quick.toml) to 7.0e-15
    # (fig6.toml, 6000 rods); 1e-12 leaves 140x, room for scenes of more or longer rods
    assert sim.state.step == 5 and sim.max_bond_error < 1e-12


def test_a_circuit_whose_resistances_span_more_than_1e6_is_refused():
    """The Kirchhoff solve's round-off grows with the spread of the resistances: contacts of 1e16 R0
    against rods of 1 gave currents 40 times too large, with no sign, so such a circuit is refused,
    naming both keys; ideal contacts (0) and a spread of 1e6 pass."""
    circuit = GOOD + "[circuit]\ndelta_J0 = 1.0\n"
    for r in ("1e7", "1e-7"):
        msg = problems(circuit, [f"contacts.resistance={r}"])
        assert "contacts.resistance, rods.resistance: the circuit's resistances span" in msg and "1e+06" in msg
    for r in ("0", "1e6", "1e-6"):
        scenario_from_text(circuit, overrides=[f"contacts.resistance={r}"])
    # per unit length: the rods' own spread counts, times their lengths
    lengths = "rods.length={distribution='uniform',low=0.5,high=1.5}"
    per_length = "rods.resistance={distribution='constant',value=1.0,per_length=true}"
    scenario_from_text(circuit, overrides=[lengths, per_length, "contacts.resistance=4e5"])
    assert "span 0.5 to 1e+06" in problems(circuit, [lengths, per_length, "contacts.resistance=1e6"])
    scenario_from_text(GOOD, overrides=["contacts.resistance=1e30"])  # no circuit: nothing is solved


def test_two_level_lengths_whose_drawn_mean_is_off_1_are_refused():
    """Exactly round(high_fraction * count) rods are long: 4 rods with a fraction 0.1 of long ones get
    none, and every rod would be 0.5 long, not the unit of length; 10 rods get one, a mean of 1."""
    law = "rods.length={distribution='two_level',low=0.5,high=5.5,high_fraction=0.1}"
    msg = problems(GOOD, [law, "rods.count=4"])
    assert "rods.length: 0 of 4 rods get the high value" in msg and "their mean is 0.5, not 1" in msg
    scenario_from_text(GOOD, overrides=[law, "rods.count=10"])


def test_an_output_file_that_names_a_folder_is_refused():
    """--set output.file=sub/ passed, and the run went to a file named "sub"."""
    for name in ("sub/", "runs/..", "."):
        assert "names a folder, not a file" in problems(GOOD, [f"output.file='{name}'"])
    scenario_from_text(GOOD, overrides=["output.file='sub/run.h5'"])


def test_a_key_of_a_law_given_as_a_bare_number_sets_that_key_of_its_table():
    """rods.length = 1 is the constant law of value 1; --set rods.length.value=1.2 on top of it was refused
    as "rods.length is a value, not a table"."""
    sc = scenario_from_text(GOOD, overrides=["rods.length=1", "rods.length.value=1"])
    assert sc.params.rods.length.distribution == "constant" and sc.params.rods.length.value == 1.0
    assert "integrator.dt is a value, not a table" in problems(GOOD, ["integrator.dt=1e-3", "integrator.dt.x=1"])
