"""Accurate defaults: every accuracy knob defaults to the setting that meets the accuracy
docs/performance.md states for it, and a shipped scene that sets a faster one says so on the line
that sets it (``[accuracy knob: ...]`` with the error it carries)."""

import re
import tomllib
from pathlib import Path

import pytest

from selfas_graph.io.scenario import load_scenario
from selfas_graph.model.accuracy import ACCURACY_RULES, short_of_accuracy
from selfas_graph.model.params import Parameters

SCENARIOS = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))


def _key_lines(text):
    """Dotted key -> the source line that sets it, with the comment lines that follow it (a setting's
    comment may run over several lines, each starting with '#')."""
    out, section, last = {}, "", None
    for line in text.splitlines():
        stripped = line.strip()
        m = re.match(r"^\[([^\]]+)\]", stripped)
        if m:
            section, last = m.group(1).strip(), None
            continue
        m = re.match(r"^([A-Za-z_][A-Za-z0-9_]*)\s*=", stripped)
        if m:
            last = f"{section}.{m.group(1)}" if section else m.group(1)
            out[last] = line
        elif stripped.startswith("#") and last is not None:
            out[last] += "\n" + line
        elif not stripped:
            last = None
    return out


def test_the_defaults_meet_every_stated_accuracy():
    """A scene of every term at the defaults is short of no stated accuracy."""
    full = {name: {} for name in ("tip_magnetic", "yukawa", "current_field", "current_lorentz")}
    p = Parameters.from_dict({"rods": {"count": 10}, "forces": full | {"electrodes": {}}, "circuit": {}})
    assert short_of_accuracy(p) == []


def test_every_rule_reads_its_own_setting():
    """``rule.value`` reads the key it names (the dry run prints it beside the stated accuracy), in a
    case (i) scene with every tree on and a case (ii) scene: between them every rule applies."""
    trees = {"method": "tree"}
    case_i = Parameters.from_dict(
        {
            "rods": {"count": 10},
            "forces": {"tip_magnetic": trees, "yukawa": {}, "current_field": trees, "current_lorentz": trees}
            | {"electrodes": {}},
            "circuit": {},
            "integrator": {"slow_every": 4},
        }
    )
    case_ii = load_scenario(SCENARIOS[0].with_name("fig8_quick.toml")).params
    seen = set()
    for p in (case_i, case_ii):
        for rule in ACCURACY_RULES:
            if rule.applies(p):
                section, *rest = rule.key.split(".")
                expected = getattr(p, section)
                for part in rest:
                    expected = getattr(expected, part)
                assert rule.value(p) == expected and rule.value(p) is not None
                seen.add(rule.key)
    assert seen == {r.key for r in ACCURACY_RULES}
    assert case_i.integrator.slow_every == ACCURACY_RULES[1].value(case_i) == 4


@pytest.mark.parametrize(
    "angle, groups, short",
    [
        (0.55, 1024, []),
        (0.55, 4096, []),
        (0.475, 128, []),
        (0.3, 16, []),
        (0.55, 128, ["forces.tip_magnetic.group_size"]),
        (0.6, 1024, ["forces.tip_magnetic.opening_angle"]),
        (0.6, 128, ["forces.tip_magnetic.opening_angle", "forces.tip_magnetic.group_size"]),
    ],
)
def test_the_tree_is_short_of_its_accuracy_by_its_angle_or_its_groups(angle, groups, short):
    """The tree meets its stated error at the default groups of 1024 up to opening angle 0.55, and at
    any group size up to 0.475 (groups of 128 at 0.475 were the defaults before 0.4.1, measured alike)."""
    tm = {"opening_angle": angle, "group_size": groups}
    p = Parameters.from_dict({"rods": {"count": 10}, "forces": {"tip_magnetic": tm}})
    assert [r.key for r in short_of_accuracy(p) if r.key.startswith("forces.tip_magnetic")] == short


@pytest.mark.parametrize("term", ["current_field", "current_lorentz"])
def test_quadrupoles_in_the_current_tree_are_named_faster_than_accurate(term):
    """order = 2 of a current term's tree is below its stated accuracy; on the direct sum it changes nothing."""
    base = {"rods": {"count": 10}, "forces": {"electrodes": {}}, "circuit": {"delta_J0": 1.0}}

    def short(**knobs):
        p = Parameters.from_dict({**base, "forces": {"electrodes": {}, term: knobs}})
        return [r.key for r in short_of_accuracy(p) if r.key.startswith(f"forces.{term}.order")]

    assert short(method="tree", order=2) == [f"forces.{term}.order"]
    assert short(method="tree", order=3) == short(method="direct", order=2) == []


def test_every_rule_names_a_real_key():
    p = Parameters()
    for rule in ACCURACY_RULES:
        section, *rest = rule.key.split(".")
        assert hasattr(p, section), rule.key


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.name)
def test_shipped_scenes_name_every_faster_setting_with_its_error(path):
    """Each setting below its stated accuracy is marked ``[accuracy knob: ...]`` on its line, with the error."""
    text = path.read_text()
    tomllib.loads(text)  # a valid file
    lines = _key_lines(text)
    for rule in short_of_accuracy(load_scenario(path).params):
        line = lines.get(rule.key)
        if line is None and rule.key == "forces.current_lorentz.near_range":
            line = lines.get("forces.current_lorentz.quadrature_points")
        if line is None and rule.key == "forces.tip_magnetic.group_size":
            line = lines.get("forces.tip_magnetic.opening_angle")
        assert line is not None, f"{path.name}: {rule.key} is below its stated accuracy ({rule.stated}) by a default"
        assert "[accuracy knob:" in line, f"{path.name}: {rule.key} is set faster than accurate without saying so"
        assert re.search(r"\d", line.split("[accuracy knob:", 1)[1]), f"{path.name}: {rule.key} names no error"


def test_a_null_model_is_told_what_it_still_keeps():
    """contacts.enabled = false alone keeps aggregation (the forces make tips stick): a note says
    which forces to remove; the free-rod null model (no tip-tip force, no tip brake) gets none of it."""
    from selfas_graph.io.scenario import load_scenario
    from selfas_graph.model.accuracy import null_model_notes

    fig2 = Path(__file__).resolve().parents[2] / "scenarios" / "fig2.toml"
    no_circuit = ["forces.current_field=false", "forces.current_lorentz=false", "circuit=false"]
    notes = null_model_notes(load_scenario(fig2, overrides=["contacts.enabled=false", *no_circuit]).params)
    assert any("forces.tip_magnetic=false and forces.tip_brake=false" in n for n in notes)
    free = ["forces.tip_magnetic=false", "forces.tip_brake=false", "forces.current_field=false"]
    free += ["forces.current_lorentz=false", "circuit=false"]
    assert not any("stick" in n for n in null_model_notes(load_scenario(fig2, overrides=free).params))
    assert null_model_notes(load_scenario(fig2).params) == []
