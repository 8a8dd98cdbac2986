"""The run loop: time steps of a model with statistics rows, field output, progress display,
checkpoints and the stops (end time, step limit, steady state, blow-up, a stop request), and the
settings of the ``time``, ``output`` and ``blowup`` config sections."""

from convection.run.loop import BlowUp, LoopSettings, OutputSettings, RunSummary, TimeSettings, run

__all__ = ["BlowUp", "LoopSettings", "OutputSettings", "RunSummary", "TimeSettings", "run"]
