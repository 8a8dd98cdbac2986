"""Progress display on rank 0: a bar on a terminal, plain lines otherwise."""

from __future__ import annotations

import os
import sys
import time
from typing import TextIO

from convection.launch import launched_rank

__all__ = ["Progress", "is_terminal"]


def is_terminal(stream: TextIO) -> bool:
    """Whether ``stream`` ends on a terminal.

    Under OpenMPI the ranks' standard output is a pseudo-terminal even when mpirun itself writes
    into a file or a pipe, so under a launcher the answer is taken from the launcher's (the
    parent's) standard output instead.
    """
    if not stream.isatty():
        return False
    if launched_rank() is None:
        return True
    try:
        target = os.readlink(f"/proc/{os.getppid()}/fd/1")
    except OSError:
        return False
    return target.startswith(("/dev/pts/", "/dev/tty"))


class Progress:
    """Shows step, time, dt, vrms and an ETA from the simulated-time rate.

    The ETA is the wall time per unit of simulated time so far times the simulated time left: to
    the end time, or, for a run that stops at a steady state, to the steady state when
    :meth:`update` is given an estimate of that (``remaining``; see
    :meth:`convection.run.steady.SteadyRate.remaining`), whichever is sooner. The lines then say
    ``ETA 120s (steady)`` instead of ``ETA 3600s``.

    Args:
        end_time: Simulated end time (the bar's total).
        mode: "auto" (bar on a terminal, lines otherwise), "bar", "lines" or "none".
        every: Steps between plain lines.
        enabled: False on ranks other than 0.
        stream: Where to write (default stderr for the bar, stdout for lines).
        units: Show times and velocities in a model's units: ``(time factor, time unit, velocity
            factor, velocity unit)``, each factor turning the solver's number into the unit.
    """

    def __init__(self, end_time: float, /, *, mode: str = "auto", every: int = 10, enabled: bool = True,
                 stream: TextIO | None = None, units: tuple[float, str, float, str] | None = None) -> None:
        self.end_time = end_time
        self._units = units or (1.0, "", 1.0, "")
        self.every = max(1, every)
        self._start = time.monotonic()
        self._bar = None
        self._stream = stream
        if not enabled or mode == "none":
            self.mode = "none"
            return
        out = stream or sys.stdout
        if mode == "auto":
            mode = "bar" if is_terminal(out) else "lines"
        self.mode = mode
        if mode == "bar":
            from tqdm import tqdm

            self._bar = tqdm(total=end_time * self._units[0], unit="t", file=stream or sys.stderr, dynamic_ncols=True,
                             bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g}" + self._label(1)
                             + " [{elapsed}<{remaining}] {postfix}")

    def time_text(self, t: float) -> str:
        """A time in the shown unit (``"0.875 Myr"``; nondimensional: ``"0.000110457"``)."""
        return f"{t * self._units[0]:.6g}{self._label(1)}"

    def velocity_text(self, v: float) -> str:
        """A velocity in the shown unit."""
        return f"{v * self._units[2]:.6g}{self._label(3)}"

    def _label(self, i: int) -> str:
        return f" {self._units[i]}" if self._units[i] else ""

    def eta(self, t: float, remaining: float | None = None) -> float:
        """Seconds left, extrapolated from the simulated-time rate so far (inf before any progress):
        to the end time, or over ``remaining`` simulated time if that is sooner."""
        elapsed = time.monotonic() - self._start
        if t <= 0.0:
            return float("inf")
        left = max(self.end_time - t, 0.0)
        if remaining is not None:
            left = min(left, max(remaining, 0.0))
        return elapsed * left / t

    def update(self, step: int, t: float, dt: float, vrms: float, *, extra: str = "", force: bool = False,
               remaining: float | None = None) -> None:
        """Show a step; ``remaining``: the simulated time estimated to a steady state (None: none)."""
        tf, vf = self._units[0], self._units[2]
        steady = remaining is not None and remaining < self.end_time - t
        if self.mode == "bar" and self._bar is not None:
            if steady:
                extra = f"{extra} steady in ~{self.eta(t, remaining):.0f}s".strip()
            self._bar.set_postfix_str(f"step={step} dt={dt * tf:.3g}{self._label(1)} "
                                      f"vrms={vrms * vf:.5g}{self._label(3)} {extra}".strip(), refresh=False)
            self._bar.update(min(t, self.end_time) * tf - self._bar.n)
        elif self.mode == "lines" and (force or step % self.every == 0):
            eta = self.eta(t, remaining)
            eta_text = "?" if eta == float("inf") else f"{eta:.0f}s" + (" (steady)" if steady else "")
            line = (f"step {step:6d}  t={t * tf:.6g}{self._label(1)}  dt={dt * tf:.4g}{self._label(1)}  "
                    f"vrms={vrms * vf:.6g}{self._label(3)}  ETA {eta_text}")
            print(f"{line}  {extra}".rstrip(), file=self._stream or sys.stdout, flush=True)

    def message(self, text: str) -> None:
        if self.mode == "bar" and self._bar is not None:
            self._bar.write(text)
        elif self.mode in ("lines", "bar"):
            print(text, file=self._stream or sys.stdout, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
