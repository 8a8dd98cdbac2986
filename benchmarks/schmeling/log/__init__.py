"""Scripts that measured the runs logged in benchmarks/schmeling/log/: ``python -m benchmarks.schmeling.log.<script>``."""
