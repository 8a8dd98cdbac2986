"""Benchmark scripts of benchmarks/phase_transitions/ (README.md there): ``python -m benchmarks.phase_transitions.<script>``."""
