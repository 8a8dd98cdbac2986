"""Benchmark scripts of benchmarks/free_surface/ (README.md there): ``python -m benchmarks.free_surface.<script>``."""
