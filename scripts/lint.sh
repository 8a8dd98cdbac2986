#!/usr/bin/env bash
# Lint (ruff) and type check (mypy) with the versions and settings of pyproject.toml ([tool.ruff],
# [tool.mypy]; the pinned `lint` extra that scripts/setup.sh installs). scripts/test.sh runs this
# first; alone: `bash scripts/lint.sh` (sets the venv up if needed) or `bash scripts/lint.sh PYTHON`
# with a Python that has ruff and mypy. Exit code: 0 when both are clean, else the first failure's.
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
py="${1:-}"
if [ -z "$py" ]; then
    py="$(bash scripts/setup.sh | tail -n 1)" || exit 1
fi
# The caches live in the venv: one per Debian release (scripts/in_release_root.sh mounts a root's
# own venv over .venv), none in the work tree.
cache="$("$py" -c 'import sys; print(sys.prefix)')/lint-cache"
export RUFF_CACHE_DIR="$cache/ruff" MYPY_CACHE_DIR="$cache/mypy"
status=0
echo "== ruff check . =="
"$py" -m ruff check . || status=$?
echo "== mypy (convection, particles, fembase, benchmarks/harness.py, benchmarks/common.py) =="
"$py" -m mypy || { rc=$?; [ "$status" -eq 0 ] && status=$rc; }
exit "$status"
