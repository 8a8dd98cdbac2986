"""Benchmark scripts of benchmarks/viscoelastic/ (README.md there): ``python -m benchmarks.viscoelastic.<script>``."""
