"""What a run writes and reads back: field series (XDMF/HDF5), the statistics file, checkpoints,
and pictures of a run folder. Names are imported when first used: the pictures and the statistics
reader need neither DOLFINx nor MPI."""

from convection._lazy import lazy_exports

__all__ = ["Checkpointer", "FieldOutput", "StatisticsWriter", "plot_run", "plot_snapshots", "read_table"]

__getattr__, __dir__ = lazy_exports(__name__, {"Checkpointer": "checkpoint", "FieldOutput": "fields",
                                               "StatisticsWriter": "statistics", "read_table": "statistics",
                                               "plot_run": "pictures", "plot_snapshots": "pictures"})
