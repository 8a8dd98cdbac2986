"""Benchmark scripts of benchmarks/compressible/ (README.md there): ``python -m benchmarks.compressible.<script>``."""
