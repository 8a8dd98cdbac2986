#!/usr/bin/env bash
# The same benchmarks on this machine's Debian and in a root of the other release
# (scripts/in_release_root.sh), compared number by number: benchmarks/releases/run.py measure on
# each side, then compare. Writes output/releases/<codename>.json for each and the table to
# benchmarks/releases/results.md; exits 1 if a number differs by more than asked.
#
# Usage: scripts/compare_releases.sh [OTHER_RELEASE]   (default: trixie on Debian 12, bookworm on 13)
# Cost on the 2-core machine: about 4 min per release.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
host_release="$(. /etc/os-release && echo "${VERSION_CODENAME:-}")"
if [ "$host_release" = trixie ]; then other=bookworm; else other=trixie; fi
other="${1:-$other}"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
export OMPI_MCA_btl_tcp_disable_family=6   # Open MPI 5's IPv6 pairing warning (scripts/test.sh)

py="$(bash scripts/setup.sh | tail -n 1)"
echo "== $host_release (this machine) ==" >&2
a="$("$py" benchmarks/releases/run.py measure --out output/releases | tail -n 1)"
echo "== $other (scripts/in_release_root.sh) ==" >&2
bash scripts/in_release_root.sh "$other" -- bash scripts/setup.sh >/dev/null
b="$(bash scripts/in_release_root.sh "$other" -- .venv/bin/python benchmarks/releases/run.py measure --out output/releases | tail -n 1)"
"$py" benchmarks/releases/run.py compare "$a" "$b" --table benchmarks/releases/results.md
