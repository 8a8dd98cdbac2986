"""Benchmark scripts of benchmarks/schmeling/ (README.md there): ``python -m benchmarks.schmeling.<script>``."""
