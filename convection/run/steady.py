"""Steady-state stops, and how much model time a run that stops at steady state still needs.

Two tests watch the relative change of the watched quantities ``q`` (vrms and the Nusselt number,
those a model has):

- :class:`SteadyState` (``time.steady_state_tolerance`` over ``time.steady_state_window`` steps):
  ``max_q max_{i in last window steps} |q_i - q_n| / |q_n| < tolerance``. Its window is a number of
  steps, so the model time it spans, and with it when a run stops, depends on the step length.
- :class:`SteadyRate` (``time.steady_state_rate`` over ``time.steady_state_time_window`` = tau,
  model time): the relative change per unit model time over the last tau,

      R(t) = max_q  max_{t - tau <= s <= t} |q(s) - q(t)| / (|q(t)| tau),

  with ``q(t - tau)`` interpolated linearly between the two steps around it. The run stops when
  ``R(t) < rate``. R depends on the history of q in model time only, so halving the step does not
  change when a run stops (to the time discretisation error of q itself). For q converging as
  ``q_inf (1 + A exp(-lambda t))``, R decays as ``exp(-lambda t)``, and the relative distance
  still left to the steady value when the run stops is about ``rate / lambda`` (for tau lambda << 1).

The remaining time (:meth:`SteadyRate.remaining`) is the convergence rate's extrapolation: a least
squares line through ``log R`` against ``t`` over the last :data:`FIT_WINDOWS` tau, slope
``-lambda``; R reaches the rate after ``log(R(t) / rate) / lambda``. It is None while R does not
decay (no estimate; the progress display falls back to the end time).
"""

from __future__ import annotations

from typing import Any, NamedTuple
from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["FIT_WINDOWS", "SteadyRate", "SteadyState", "decay_estimate"]

FIT_WINDOWS = 2.0
"""The remaining-time fit uses the change rates R of the last ``FIT_WINDOWS * tau`` of model time."""

COLUMNS = ("vrms", "nusselt")


def _entry(values: Mapping[str, float | None], columns: Sequence[str]) -> list[float]:
    return [np.nan if (v := values.get(c)) is None else float(v) for c in columns]


class SteadyState:
    """Stop when every watched quantity changed by less than ``tolerance`` (relative) over ``window`` steps.

    Quantities that are None (not in this model, e.g. ``nusselt`` without a temperature equation)
    are left out; the test needs at least one.
    """

    def __init__(self, tolerance: float | None, window: int, columns: Sequence[str] = COLUMNS) -> None:
        self.tolerance = tolerance
        self.window = window
        self.columns = tuple(columns)
        self._history: list[tuple[int, list[float]]] = []

    def __call__(self, values: Mapping[str, float | None], step: int | None = None, time: float | None = None) -> bool:
        """Add the values of a step (a value for the step already added last replaces it)."""
        if step is not None and self._history and self._history[-1][0] == step:
            self._history.pop()
        self._history.append((-1 if step is None else step, _entry(values, self.columns)))
        if self.tolerance is None or len(self._history) <= self.window:
            return False
        recent = np.array([e for _, e in self._history[-self.window - 1:]])
        present = ~np.all(np.isnan(recent), axis=0)
        if not present.any():
            return False
        recent = recent[:, present]
        scale = np.maximum(np.abs(recent[-1]), 1e-300)
        change = np.max(np.abs(recent - recent[-1]), axis=0) / scale
        return bool(np.all(change < self.tolerance))

    def remaining(self) -> float | None:
        """No estimate of the model time to a steady state (a window of steps has no time scale)."""
        return None

    def state(self) -> list[list[Any]]:
        """The last ``window + 1`` entries (what a checkpoint keeps; JSON-able)."""
        return [[step, [None if np.isnan(v) else v for v in entry]] for step, entry in self._history[-self.window - 1:]]

    def restore(self, state: list[list[Any]]) -> None:
        self._history = [(int(step), [np.nan if v is None else float(v) for v in entry]) for step, entry in state]


class Decay(NamedTuple):
    """A least-squares fit ``log R = log R_0 - rate * (t - t_0)``.

    Attributes:
        rate: The decay rate lambda (per unit model time); positive when R decays.
        remaining: Model time until R reaches the tolerance (0 if it is there; None if R does not decay).
    """

    rate: float
    remaining: float | None


def decay_estimate(times: Sequence[float], rates: Sequence[float], tolerance: float, /) -> Decay | None:
    """Fit ``log(rates)`` against ``times`` by least squares and extrapolate to ``tolerance``.

    Args:
        times: Model times, shape=(n,).
        rates: Positive change rates R at those times, shape=(n,).
        tolerance: The R to reach.

    Returns:
        The fit (None with fewer than three points or no spread in time); ``remaining`` is measured
        from the last time, from the fitted line's value there.
    """
    t = np.asarray(times, dtype=float)
    r = np.asarray(rates, dtype=float)
    keep = np.isfinite(r) & (r > 0.0)
    t, r = t[keep], r[keep]
    if t.size < 3 or np.ptp(t) <= 0.0:
        return None
    slope, intercept = np.polyfit(t - t[-1], np.log(r), 1)
    decay = -float(slope)
    if decay <= 0.0:
        return Decay(decay, None)
    return Decay(decay, max(float(intercept - np.log(tolerance)) / decay, 0.0))


class SteadyRate:
    """Stop when the relative change per unit model time ``R(t)`` of every watched quantity is below
    ``rate`` (module docstring); the steps' model times define the window, not their count.

    Args:
        rate: The tolerance on R (per unit model time); None: no test (the history is kept anyway).
        window: tau, the model time R is measured over.
        columns: The watched quantities (missing ones, None, are left out).
    """

    def __init__(self, rate: float | None, window: float, columns: Sequence[str] = COLUMNS) -> None:
        self.rate = rate
        self.window = float(window)
        self.columns = tuple(columns)
        self._history: list[tuple[float, list[float]]] = []
        self._rates: list[tuple[float, float]] = []

    def change_rate(self) -> float | None:
        """R at the last time added, or None while the history spans less than tau."""
        if len(self._history) < 2:
            return None
        times = np.array([t for t, _ in self._history])
        now = times[-1]
        start = now - self.window
        if times[0] > start:
            return None
        values = np.array([e for _, e in self._history])
        present = ~np.all(np.isnan(values), axis=0)
        if not present.any():
            return None
        values = values[:, present]
        inside = times > start
        first = max(int(np.argmax(inside)) - 1, 0)  # the last step at or before t - tau
        t0, t1 = times[first], times[first + 1]
        w = 0.0 if t1 == t0 else (start - t0) / (t1 - t0)
        at_start = (1.0 - w) * values[first] + w * values[first + 1]
        window = np.vstack([at_start, values[inside]])
        scale = np.maximum(np.abs(values[-1]), 1e-300)
        return float(np.max(np.max(np.abs(window - values[-1]), axis=0) / scale) / self.window)

    def __call__(self, values: Mapping[str, float | None], step: int | None = None, time: float | None = None) -> bool:
        """Add the values at model time ``time`` (a value at the time added last replaces it)."""
        if time is None:
            raise ValueError("the steady-state rate needs the model time of every entry")
        time = float(time)
        if self._history and self._history[-1][0] >= time:
            self._history.pop()
            if self._rates and self._rates[-1][0] >= time:
                self._rates.pop()
        self._history.append((time, _entry(values, self.columns)))
        keep_from = time - self.window
        while len(self._history) > 2 and self._history[1][0] <= keep_from:
            self._history.pop(0)
        change = self.change_rate()
        if change is None:
            return False
        self._rates.append((time, change))
        fit_from = time - FIT_WINDOWS * self.window
        while self._rates and self._rates[0][0] < fit_from:
            self._rates.pop(0)
        return self.rate is not None and change < self.rate

    def remaining(self) -> float | None:
        """Model time until ``R`` reaches the rate, from the decay of ``log R`` over the last
        :data:`FIT_WINDOWS` tau (None: no rate, too little history, or R not decaying)."""
        if self.rate is None or len(self._rates) < 3:
            return None
        times, rates = zip(*self._rates)
        if times[-1] - times[0] < 0.5 * self.window:
            return None
        fit = decay_estimate(times, rates, self.rate)
        return None if fit is None else fit.remaining

    def state(self) -> dict[str, Any]:
        """The history within tau and the change rates within the fit's span (JSON-able)."""
        return {"history": [[t, [None if np.isnan(v) else v for v in entry]] for t, entry in self._history],
                "rates": [list(item) for item in self._rates]}

    def restore(self, state: Mapping[str, Any] | None) -> None:
        state = state or {}
        self._history = [(float(t), [np.nan if v is None else float(v) for v in entry])
                         for t, entry in state.get("history", [])]
        self._rates = [(float(t), float(r)) for t, r in state.get("rates", [])]
