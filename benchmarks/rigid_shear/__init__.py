"""Benchmark scripts of benchmarks/rigid_shear/ (README.md there): ``python -m benchmarks.rigid_shear.<script>``."""
