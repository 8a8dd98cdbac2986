"""Benchmark scripts of benchmarks/scaling/ (README.md there): ``python -m benchmarks.scaling.<script>``."""
