"""Benchmark scripts of benchmarks/vanKeken/ (README.md there): ``python -m benchmarks.vanKeken.<script>``."""
