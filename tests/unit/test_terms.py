"""The force terms' own statements about themselves: the scenario keys behind each channel
(``Term.keys``), which a failure's diagnosis names, name parameters that exist."""

import dataclasses
import typing

import pytest

from selfas_graph.model.params import Parameters
from selfas_graph.model.terms.registry import FOLLOWING_TERMS, TERM_CLASSES

TERMS = [*TERM_CLASSES.values(), *(t for following in FOLLOWING_TERMS.values() for t in following)]


def _field_type(cls, name):
    """The type of dataclass ``cls``'s field ``name`` (Optional[X] read as X), or None if it has none."""
    if not dataclasses.is_dataclass(cls) or name not in {f.name for f in dataclasses.fields(cls)}:
        return None
    hint = typing.get_type_hints(cls)[name]
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    return args[0] if typing.get_origin(hint) is typing.Union and args else hint


@pytest.mark.parametrize("term", TERMS, ids=lambda t: t.__name__)
def test_every_channel_names_the_parameters_its_force_depends_on(term):
    """Each channel of each term has its keys, and each key is a parameter (a field of the
    parameter dataclasses down the dotted path), so that no diagnosis names a setting that is not."""
    assert set(term.keys) == {name for name, _ in term.channels}, term.__name__
    for channel, keys in term.keys.items():
        assert keys and isinstance(keys, tuple)
        for key in keys:
            cls = Parameters
            for part in key.split("."):
                cls = _field_type(cls, part)
                assert cls is not None, f"{term.__name__}.keys[{channel!r}]: {key} is no parameter"


def test_a_diagnosis_names_the_keys_of_the_tables_the_scene_has():
    """``ForceField.channel_keys`` gives a channel's keys without those of tables the scene leaves
    out (the Lorentz term of a scene without an external filament does not name one)."""
    from pathlib import Path

    from selfas_graph.io.scenario import load_scenario
    from selfas_graph.model.simulation import Simulation

    scene = Path(__file__).resolve().parents[2] / "scenarios" / "quick.toml"
    sim = Simulation.from_scenario(load_scenario(scene, overrides=["rods.count=20"]))
    keys = sim.force_field.channel_keys("current_lorentz")
    assert keys.startswith("circuit.delta_J0, ") and "forces.uniform_field.B" in keys
    assert "external" not in keys and "rods.resistance" in keys  # absent, it means R0 = 1: still a setting
    assert (
        sim.force_field.channel_keys("tip_magnetic")
        == "rods.magnetic_charge, rods.tip_stiffness, rods.transition_radius"
    )
    # the quick scene's electric charges follow the magnetic ones: the key a user changes is named
    assert sim.force_field.channel_keys("yukawa").startswith(
        "rods.magnetic_charge (rods.electric_charge follows it), forces.yukawa.screening_length"
    )
    assert sim.force_field.channel_keys("nonesuch") == "forces.nonesuch"
    assert sim.force_field.channel_keys(None) == "the force terms"


def test_every_term_is_exported_and_in_the_models_term_table():
    """The places that list the terms by hand (ARCHITECTURE.md 'How to add a force term', step 4): each
    term class is in ``model/terms/__init__.py``'s ``__all__``, each scenario table has its row in the
    table of docs/model.md 'Force terms', with each of the term's channels."""
    from pathlib import Path

    import selfas_graph.model.terms as terms
    from selfas_graph.model.force_params import ForceParams

    assert {t.__name__ for t in TERMS} <= set(terms.__all__)
    assert set(TERM_CLASSES) == {f.name for f in dataclasses.fields(ForceParams)}
    text = (Path(__file__).resolve().parents[2] / "docs" / "model.md").read_text()
    table = text[text.index("## 3. Force terms") : text.index("\n## 4.")]
    for name in TERM_CLASSES:
        rows = [r for r in table.splitlines() if r.startswith("|") and f"`forces.{name}`" in r]
        assert rows, f"docs/model.md 'Force terms': no row for forces.{name}"
        for cls in (TERM_CLASSES[name], *FOLLOWING_TERMS.get(name, ())):
            for channel, _ in cls.channels:
                assert any(channel in r.split("|")[3] for r in rows), (name, channel)
