"""Progress of a run on the coupler: a tqdm bar (sim time, steps/s, ETA) when the user's terminal is
interactive, plain periodic log lines otherwise (CI, files, pipes)."""
from __future__ import annotations

import sys
import time as _time


class Progress:
    def __init__(self, end_time: float, start_time: float, tty: bool, log, every_s: float = 10.0):
        self.end = end_time
        self.log = log
        self.every = every_s
        self.t_wall0 = _time.perf_counter()
        self.last_line = self.t_wall0
        self.steps0 = None
        self.bar = None
        if tty:
            from tqdm import tqdm

            self.bar = tqdm(total=end_time, initial=start_time, unit="s(sim)", file=sys.stderr,
                            bar_format="{l_bar}{bar}| t={n:.3e}/{total:.3e} s [{elapsed}<{remaining}{postfix}]")
        self.t_last = start_time

    def update(self, t: float, step: int) -> None:
        now = _time.perf_counter()
        if self.steps0 is None:
            self.steps0 = step
        rate = (step - self.steps0) / max(now - self.t_wall0, 1e-9)
        if self.bar is not None:
            self.bar.update(t - self.t_last)
            self.bar.set_postfix_str(f"step {step}, {rate:.0f} steps/s", refresh=False)
            self.t_last = t
        elif now - self.last_line >= self.every:
            frac = t / self.end if self.end > 0 else 1.0
            eta = (now - self.t_wall0) * (1 - frac) / max(frac, 1e-12) if frac > 0 else float("nan")
            self.log(f"t = {t:.4e} s ({100 * frac:.1f}%), step {step}, {rate:.0f} steps/s, ETA {eta:.0f} s")
            self.last_line = now

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
