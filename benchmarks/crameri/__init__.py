"""Benchmark scripts of benchmarks/crameri/ (README.md there): ``python -m benchmarks.crameri.<script>``."""
