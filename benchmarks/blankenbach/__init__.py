"""Benchmark scripts of benchmarks/blankenbach/ (README.md there): ``python -m benchmarks.blankenbach.<script>``."""
