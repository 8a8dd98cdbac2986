"""Benchmark scripts of benchmarks/particle_distribution/ (README.md there):
``python -m benchmarks.particle_distribution.<script>``."""
