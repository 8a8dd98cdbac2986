"""Benchmark scripts of benchmarks/shell/ (README.md there): ``python -m benchmarks.shell.<script>``."""
