#!/usr/bin/env bash
# CI on another Debian release: make a fresh root of RELEASE (default: trixie, Debian 13 with DOLFINx 0.9,
# on a Debian 12 machine; bookworm, Debian 12 with DOLFINx 0.5.2, on a Debian 13 one),
# set the project up inside it with scripts/setup.sh and run scripts/test.sh there; the exit code
# is test.sh's (or the first failing step's). The root is made in a new folder and deleted at the
# end, so every run starts from nothing, as on a new machine.
#
# Usage: scripts/ci_release.sh [RELEASE] [-- TEST.SH ARGS...]
#   bash scripts/ci_release.sh                     # what .ci/run would call: the other release
#   bash scripts/ci_release.sh trixie -- -x        # Debian 13, stop at the first failure
#   PIC_CI_KEEP_ROOT=1 bash scripts/ci_release.sh  # keep the root afterwards (its path is printed)
#   PIC_TEST_WATCHDOG=600 bash scripts/ci_release.sh # seconds per test (default 300)
# Cost from nothing on the 2-core machine (trixie, measured): debootstrap 22 s, apt 93 s (+ update),
# venv + pip ~15 s: the root and setup ~2 min 10 s, then the test suite.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"

# Default: the other of the two releases this project is checked on, so that CI covers both
# whichever one the machine runs (Debian 12 now: trixie; on a Debian 13 machine: bookworm).
host_release="$(. /etc/os-release 2>/dev/null && echo "${VERSION_CODENAME:-}")"
if [ "$host_release" = trixie ]; then release=bookworm; else release=trixie; fi
if [ "$#" -gt 0 ] && [ "$1" != "--" ]; then release="$1"; shift; fi
[ "${1:-}" = "--" ] && shift

roots="$(mktemp -d "${PIC_CI_ROOTS_PARENT:-/var/tmp}/pic-ci-roots.XXXXXX")"
export PIC_ROOTS="$roots"
cleanup() {
    if [ "${PIC_CI_KEEP_ROOT:-0}" = 1 ]; then
        echo "[ci-$release] root kept: $roots/$release" >&2
        return
    fi
    # Nothing can be mounted there (all mounts live in private namespaces); check anyway before
    # deleting, and keep rm on this file system.
    if grep -qF " $roots" /proc/self/mountinfo; then
        echo "[ci-$release] something is still mounted under $roots; not deleting it" >&2
    else
        rm -rf --one-file-system "$roots"
    fi
}
trap cleanup EXIT

t_start=$SECONDS
phase() { echo "[ci-$release] $1: $(( SECONDS - t0 )) s" >&2; }

echo "== Debian $release root (fresh, $roots) ==" >&2
t0=$SECONDS
bash scripts/release_root.sh "$release" >/dev/null
phase "root (debootstrap)"

echo "== setup inside the $release root ==" >&2
t0=$SECONDS
bash scripts/in_release_root.sh "$release" -- bash scripts/setup.sh >/dev/null
phase "setup (apt + venv + pip)"

echo "== versions inside the $release root ==" >&2
bash scripts/in_release_root.sh "$release" -- .venv/bin/python - <<'EOF' >&2 || true
import sys, dolfinx, numpy, numba, h5py
print(f"Python {sys.version.split()[0]}, DOLFINx {dolfinx.__version__}, numpy {numpy.__version__}, "
      f"numba {numba.__version__}, h5py {h5py.__version__} (MPI: {h5py.get_config().mpi})")
EOF

echo "== scripts/test.sh inside the $release root ==" >&2
t0=$SECONDS
rc=0
# A bound per test (scripts/pytest_watchdog.py: the stuck process prints its tracebacks and exits,
# and mpirun ends that collective run): while the code does not work on this release, a collective
# test whose ranks part ways (one raises, another waits in a collective) would otherwise sit until
# test.sh's 30-minute mpirun timeout, twice.
PIC_TEST_WATCHDOG="${PIC_TEST_WATCHDOG:-300}" \
    bash scripts/in_release_root.sh "$release" -- bash scripts/test.sh "$@" || rc=$?
phase "tests"
echo "[ci-$release] total: $(( SECONDS - t_start )) s, test.sh exit code $rc" >&2
exit "$rc"
