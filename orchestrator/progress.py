"""Progress of a run on the coupler: a tqdm bar (sim time, steps/s, ETA) when the user's terminal is
interactive, plain periodic log lines otherwise (CI, files, pipes).

Rates and the ETA are measured from the first update on (the end of the first step), not from the
start: the first step carries the start-up (imports, set-up, loading or compiling kernels), and a
rate that includes it predicts nonsense (an "ETA 1787 s" for a run that ends a second later).
No ETA is shown until the rate has been measured over `eta_after_s` seconds of stepping.
"""
from __future__ import annotations

import sys
import time as _time

ETA_AFTER_S = 3.0  # seconds of stepping before the rate is trusted for an ETA


def _suffix(note) -> str:
    """"; note" (note a string or a function giving one), or nothing."""
    text = note() if callable(note) else note
    return f"; {text}" if text else ""


class Progress:
    def __init__(self, end_time: float, start_time: float, tty: bool, log, every_s: float = 10.0,
                 eta_after_s: float = ETA_AFTER_S, clock=_time.perf_counter):
        self.end = end_time
        self.log = log
        self.every = every_s
        self.eta_after = eta_after_s
        self.clock = clock
        self.last_line = clock()
        self.first = None  # (wall, sim time, step) at the first update
        self.bar = None
        if tty:
            from tqdm import tqdm

            # no {remaining}: tqdm's own estimate would include the start-up (see the module doc)
            self.bar = tqdm(total=end_time, initial=start_time, unit="s(sim)", file=sys.stderr,
                            bar_format="{l_bar}{bar}| t={n:.3e}/{total:.3e} s [{elapsed}{postfix}]")
        self.t_last = start_time

    def eta(self, now: float, t: float) -> float | None:
        """Seconds left at the rate measured since the first update; None until it is measured."""
        if self.first is None:
            return None
        w0, t0, _ = self.first
        if now - w0 < self.eta_after or t <= t0:
            return None
        return (self.end - t) * (now - w0) / (t - t0)

    def status(self, now: float, t: float, step: int) -> str:
        w0, _, s0 = self.first
        rate = (step - s0) / (now - w0) if now > w0 else 0.0
        eta = self.eta(now, t)
        return f"step {step}, {rate:.0f} steps/s, " + (f"ETA {eta:.0f} s" if eta is not None else "ETA --")

    def update(self, t: float, step: int, note=None) -> None:
        """note: what the solvers add to the line (an implicit solver's step and Newton iterations): a
        string, or a function giving it, called only when a line is written (not every step)."""
        now = self.clock()
        if self.first is None:
            self.first = (now, t, step)
        if self.bar is not None:
            self.bar.update(t - self.t_last)
            self.bar.set_postfix_str(self.status(now, t, step) + _suffix(note), refresh=False)
            self.t_last = t
        elif now - self.last_line >= self.every:
            frac = t / self.end if self.end > 0 else 1.0
            self.log(f"t = {t:.4e} s ({100 * frac:.1f}%), {self.status(now, t, step)}" + _suffix(note))
            self.last_line = now

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
