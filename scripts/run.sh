#!/usr/bin/env bash
# Set everything up (idempotent) and run the default job: the van Keken et al. (1997) case 1a
# Rayleigh-Taylor benchmark (particle composition, adaptive mesh) to t = 300 on 2 MPI ranks, which
# covers the first vrms peak. Writes output/vanKeken_1a/results.md (our peak vs the published one)
# and output/vanKeken_1a/vrms.png (our curve against the published peak), then snapshot pictures of
# the composition with the particles on top at t = 0, 100, 200, 300 (output/vanKeken_1a/1a/snapshots/).
# Extra arguments go to benchmarks/vanKeken/run.py (e.g. --end 2000 for the whole published run).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
py="$(bash scripts/setup.sh | tail -n 1)"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# Open MPI 5 (Debian 13) warns on every rank about IPv6 interface pairing: one machine, IPv4 only.
export OMPI_MCA_btl_tcp_disable_family=6
ranks="${RANKS:-2}"
"$py" -m benchmarks.vanKeken.run --case 1a --ranks "$ranks" --end 300 --out output/vanKeken_1a \
    --set output.fields_every=10 --set particles.output.every_time=100 \
    --set "particles.output.properties=[composition]" "$@"
# Snapshots of the composition with the particles on top (output/vanKeken_1a/1a/snapshots/).
"$py" -m convection.plot output/vanKeken_1a/1a --times 0 100 200 300
echo "picture: $here/output/vanKeken_1a/vrms.png   table: $here/output/vanKeken_1a/results.md"
echo "snapshots: $here/output/vanKeken_1a/1a/snapshots/"
