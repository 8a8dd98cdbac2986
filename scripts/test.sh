#!/usr/bin/env bash
# Set everything up (idempotent), lint and type check (scripts/lint.sh: ruff, mypy), and run the
# test suite: the collective tests under MPI's launcher
# with 2 ranks and 3 ranks (Open MPI's mpirun --oversubscribe, or MPICH's mpiexec on the PyPI route:
# python -m convection.launch N tells which), then the serial tests in pytest-xdist workers (exit 5, none collected,
# fails). Extra arguments go to every pytest call. PIC_DOLFINX=pypi: the PyPI route (setup.sh).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
py="$(bash scripts/setup.sh | tail -n 1)"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
# Open MPI 5.0.7 (Debian 13) prints "Unable to find reachable pairing between local and remote
# interfaces" from its TCP BTL on every rank when a host has IPv6 addresses beside IPv4 (open-mpi/ompi
# issue 14079), which breaks the tests that read stderr; the runs here are on one machine, so the
# TCP BTL keeps IPv4 only. Harmless with Open MPI 4 (Debian 12).
export OMPI_MCA_btl_tcp_disable_family=6
export PYTHONDONTWRITEBYTECODE=1
# PIC_TEST_WATCHDOG=SECONDS: a test running longer ends its process (scripts/pytest_watchdog.py),
# so that ranks that parted ways cannot hang a run; scripts/ci_release.sh sets it.
if [ -n "${PIC_TEST_WATCHDOG:-}" ]; then
    export PYTHONPATH="$here/scripts${PYTHONPATH:+:$PYTHONPATH}"
    set -- -p pytest_watchdog "$@"
fi

status=0

# Lint and type check first (seconds): a failure fails the run, and the tests still run so that
# one CI run shows both.
lint=0
bash scripts/lint.sh "$py" || lint=$?
[ "$lint" -ne 0 ] && status=$lint

logdir="$(mktemp -d)"
for n in 2 3; do
    launcher="$("$py" -m convection.launch "$n")"
    mapfile -t mpirun <<< "$launcher"
    echo "== collective tests under ${mpirun[*]} =="
    rc=0
    # Rank 0 reports; the other ranks log to files that are shown when the run fails. The rank is
    # Open MPI's OMPI_COMM_WORLD_RANK or MPICH's PMI_RANK.
    timeout 1800 "${mpirun[@]}" bash -c '
        rank="${OMPI_COMM_WORLD_RANK:-${PMI_RANK:-}}"
        if [ "$rank" = 0 ]; then exec "$0" -m pytest -p no:cacheprovider --color=no "${@:2}";
        else exec "$0" -m pytest -p no:cacheprovider --color=no -q "${@:2}" > "$1/rank$rank.log" 2>&1; fi
    ' "$py" "$logdir" -m "mpi and not slow" "$@" || rc=$?
    if [ "$rc" -ne 0 ]; then
        for f in "$logdir"/rank*.log; do echo "---- $f"; tail -n 60 "$f"; done
        status=$rc
    fi
done
rm -rf "$logdir"

# Serial tests last, so the closing summary line is the main run's. They run in pytest-xdist's
# workers, one a core (PIC_TEST_WORKERS=N to choose, 0 for none), each test handed to the next idle
# worker (worksteal): on the 2-core machine this halves the phase that takes most of the time.
workers="${PIC_TEST_WORKERS:-$(nproc)}"
xdist=()
[ "$workers" -gt 1 ] && xdist=(-n "$workers" --dist worksteal)
echo "== serial tests (${workers} workers) =="
rc=0
"$py" -m pytest -m "not slow and not mpi" "${xdist[@]}" "$@" || rc=$?
[ "$rc" -ne 0 ] && status=$rc
[ "$lint" -ne 0 ] && echo "== scripts/lint.sh failed (exit $lint): see its output at the top =="
exit "$status"
