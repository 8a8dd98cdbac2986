"""Benchmark scripts of benchmarks/localisation/ (README.md there): ``python -m benchmarks.localisation.<script>``."""
