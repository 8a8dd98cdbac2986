"""Benchmark scripts of benchmarks/tackley_king/ (README.md there): ``python -m benchmarks.tackley_king.<script>``."""
