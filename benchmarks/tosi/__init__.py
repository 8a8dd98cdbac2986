"""Benchmark scripts of benchmarks/tosi/ (README.md there): ``python -m benchmarks.tosi.<script>``."""
