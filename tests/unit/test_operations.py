"""Operations with triggers: what acts after which step of Simulation.run."""

import numpy as np
import pytest

from conftest import SMALL_CIRCUIT_SCENE
from selfas_graph.io.h5md import NullWriter
from selfas_graph.io.scenario import scenario_from_text
from selfas_graph.model.operations import Always, Operation, Periodic, RunInterrupted, When
from selfas_graph.model.simulation import Simulation


def _sim():
    return Simulation.from_scenario(scenario_from_text(SMALL_CIRCUIT_SCENE))


class _Log(Operation):
    """Records the time steps it acted on."""

    def __init__(self, trigger, final=False):
        self.trigger, self.final, self.steps = trigger, final, []

    def act(self, sim, i, n_steps):
        self.steps.append(sim.state.step)


def test_triggers():
    assert [s for s in range(10) if Periodic(4)(s)] == [0, 4, 8]
    assert [s for s in range(10) if Periodic(4, phase=6)(s)] == [2, 6]
    assert all(Always()(s) for s in range(3))
    flag = [False]
    w = When(lambda: flag[0])
    assert not w(1)
    flag[0] = True
    assert w(1)


def test_attached_operations_act_on_their_trigger_in_every_run_and_run_is_the_step_loop():
    """An operation in sim.operations acts after the steps its trigger names, in every run call;
    with final = True also after a run's last step. The frame writer writes frame 0, then every
    output interval (100 steps here) and at the end."""
    sim = _sim()
    every7, final = _Log(Periodic(7)), _Log(Periodic(1000), final=True)
    sim.operations += [every7, final]
    writer = NullWriter()
    sim.run(t_end=0.02, writer=writer)  # 40 steps
    sim.run(t_end=0.06)  # 80 more, no writer
    assert every7.steps == list(range(7, 121, 7))
    assert final.steps == [40, 120]
    assert writer.n_frames == 2  # frame 0 and the end of the first run (no multiple of 100 in 1..40)


def test_an_operation_need_not_subclass_operation_and_one_without_act_is_refused_by_name():
    """The docs make start, flush and finish optional: an object with only a trigger and act used to
    fail with AttributeError: 'start'. One without act is refused naming its place in sim.operations."""

    class Duck:
        trigger = Periodic(5)

        def __init__(self):
            self.steps = []

        def act(self, sim, i, n_steps):
            self.steps.append(sim.state.step)

    sim = _sim()
    duck = Duck()
    sim.operations.append(duck)
    sim.run(t_end=0.01)  # 20 steps
    assert duck.steps == [5, 10, 15, 20]
    sim.operations.append(object())
    with pytest.raises(TypeError, match=r"sim.operations\[1\]: an operation needs a trigger"):
        sim.run(t_end=0.02)
    assert sim.state.step == 20


def test_progress_counts_steps_of_the_run_and_stop_raises_after_a_checkpoint():
    sim = _sim()
    sim.step(3)
    seen = []
    sim.run(
        t_end=sim.state.time + 10 * sim.dt, progress=lambda s, i, n: seen.append((s.state.step, i, n)), progress_every=4
    )
    assert seen == [(7, 4, 10), (11, 8, 10), (13, 10, 10)]

    class Checkpointer:
        written = []

        def due(self):
            return False

        def write(self, s):
            self.written.append(s.state.step)

    ck = Checkpointer()
    with pytest.raises(RunInterrupted) as exc:
        sim.run(t_end=sim.state.time + 10 * sim.dt, checkpointer=ck, stop=lambda: sim.state.step >= 15)
    assert exc.value.step == 15 and ck.written == [15]
    assert np.isfinite(sim.state.position).all()


@pytest.mark.parametrize("t_end", [[0.2], "0.2", True, np.True_])
def test_run_refuses_a_time_that_is_not_a_number(t_end):
    """A list, a string or a boolean is not a time: float() took '0.2' and True (= 1.0) without a word."""
    with pytest.raises(TypeError, match="t_end must be a time"):
        _sim().run(t_end)


def test_a_float32_time_is_the_decimal_it_prints_as():
    """np.float32(0.02) is the time 0.02, as in a scene file, not a time between two steps."""
    sim = _sim()
    assert sim.steps_to(np.float32(0.02)) == sim.steps_to(0.02)
