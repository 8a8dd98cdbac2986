"""The run loop: time steps of a model with statistics rows, field output, progress display,
checkpoints and the stops (end time, step limit, steady state, blow-up, a stop request), and the
settings of the ``time`` and ``blowup`` config sections (the ``output`` section is io's,
:class:`convection.io.fields.OutputSettings`)."""

from convection.run.loop import BlowUp, LoopSettings, RunSummary, TimeSettings, run

__all__ = ["BlowUp", "LoopSettings", "RunSummary", "TimeSettings", "run"]
