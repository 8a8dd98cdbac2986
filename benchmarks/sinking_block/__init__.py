"""Benchmark scripts of benchmarks/sinking_block/ (README.md there): ``python -m benchmarks.sinking_block.<script>``."""
