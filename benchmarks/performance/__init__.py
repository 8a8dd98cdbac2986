"""Benchmark scripts of benchmarks/performance/ (README.md there): ``python -m benchmarks.performance.<script>``."""
