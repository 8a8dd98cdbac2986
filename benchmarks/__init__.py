"""The benchmarks, one folder (a package) each: run a script from the project root as
``python -m benchmarks.<folder>.<script>``; tests import it as ``from benchmarks.<folder> import
<script>``. The shared harness is :mod:`benchmarks.harness`, the run and figure helpers
:mod:`benchmarks.common`."""
