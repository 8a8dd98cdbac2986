"""Benchmark scripts of benchmarks/releases/ (README.md there): ``python -m benchmarks.releases.<script>``."""
