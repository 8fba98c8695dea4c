"""Progress of a run on the terminal: a tqdm bar (:class:`Bar`) or plain periodic lines (:class:`Lines`).

Both are called as ``reporter(sim, done, total)`` by :func:`selfas_graph.lifecycle.run_to_file` and
show the time, the contacts and, with a circuit, the short circuit and the current
(:func:`status_text`).
"""

import sys
import time


def fmt_time(seconds):
    seconds = max(0, int(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m{s:02d}s" if h else f"{m}m{s:02d}s"


def status_text(sim) -> str:
    """Contacts, conductor contacts, the short circuit and the current, for the progress display."""
    st = sim.status()
    parts = [f"contacts {st['contacts']}"]
    if sim.params.forces.electrodes is not None:
        parts.append(f"on electrodes {st['electrode_contacts']}")
    if sim.params.forces.external_filament is not None:
        parts.append(f"on filament {st['filament_contacts']}")
    if sim.params.circuit is not None:
        sc = st["short_circuit_time"]
        parts.append(f"short circuit at t = {sc:.4g}" if sc is not None else "no short circuit")
        parts.append(f"I = {st['total_current']:.4g} J0")
    return ", ".join(parts)


class Lines:
    """Plain progress lines, at most one every ``period`` wall seconds (and at the end)."""

    def __init__(self, stream, period=10.0):
        self.stream, self.period = stream, period
        self.first = None  # (wall time, steps done) at the first line: the rate is timed from there on
        self.last = -1e9

    def __call__(self, sim, done, total):
        now = time.perf_counter()
        if now - self.last < self.period and done < total:
            return
        self.last = now
        if self.first is None or done <= self.first[1]:
            # the steps before the first line include compiling the kernels (a minute on a fresh
            # installation): a rate from them would promise hours
            self.first = self.first or (now, done)
            speed = "-- steps/s  ETA --"
        else:
            rate = (done - self.first[1]) / max(now - self.first[0], 1e-9)
            speed = f"{rate:.0f} steps/s  ETA {fmt_time((total - done) / rate)}"
        print(
            f"t = {sim.state.time:.4g} / {sim.params.run.t_end:.4g}  step {sim.state.step}  "
            f"{percent(sim.state.step, sim.state.step - done + total):5.1f}%  {speed}  {status_text(sim)}",
            file=self.stream,
            flush=True,
        )

    def close(self):
        pass


def percent(step, last_step):
    """How far a run is, in % of all its steps (a resumed run counts those before the checkpoint)."""
    return 100 * step / max(last_step, 1)


class Bar:
    """A tqdm bar over all the run's steps (a resumed run's bar starts at its checkpoint's step)."""

    def __init__(self, total, t_end, start=0):
        from tqdm import tqdm

        self.bar = tqdm(
            initial=start,
            total=start + total,
            unit="step",
            dynamic_ncols=True,
            file=sys.stderr,
            bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}, {rate_fmt}] {postfix}",
        )
        self.t_end = t_end
        self.n = 0

    def __call__(self, sim, done, total):
        self.bar.update(done - self.n)
        self.n = done
        self.bar.set_postfix_str(f"t={sim.state.time:.4g}/{self.t_end:.4g}, {status_text(sim)}", refresh=False)

    def close(self):
        self.bar.close()
