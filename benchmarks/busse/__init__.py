"""Benchmark scripts of benchmarks/busse/ (README.md there): ``python -m benchmarks.busse.<script>``."""
