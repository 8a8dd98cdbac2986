"""Benchmark scripts of benchmarks/materials/ (README.md there): ``python -m benchmarks.materials.<script>``."""
