#!/usr/bin/env bash
# The same benchmarks on this machine's Debian and in a root of the other release
# (scripts/in_release_root.sh), compared number by number: benchmarks/releases/run.py measure on
# each side, then compare. Writes output/releases/<codename>.json for each and the table to
# benchmarks/releases/results.md; exits 1 if a number differs by more than asked. Then a checkpoint
# of van Keken 1a (2 ranks, t = 60) written on each release is resumed on the other to t = 120: both
# must continue (by coordinates, with one note line) and end within 1e-12 of the uninterrupted run.
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
rm -rf output/releases/meshes   # made again by this machine's gmsh, read by the other release
echo "== $host_release (this machine) ==" >&2
a="$("$py" -m benchmarks.releases.run measure --out output/releases | tail -n 1)"
echo "== $other (scripts/in_release_root.sh) ==" >&2
bash scripts/in_release_root.sh "$other" -- bash scripts/setup.sh >/dev/null
b="$(bash scripts/in_release_root.sh "$other" -- .venv/bin/python -m benchmarks.releases.run measure --out output/releases | tail -n 1)"
compare_status=0
"$py" -m benchmarks.releases.run compare "$a" "$b" --table benchmarks/releases/results.md || compare_status=1

# --- checkpoints across the releases ---
on() {   # on RELEASE CMD...: run CMD on this machine or in the other release's root
    local where="$1"; shift
    if [ "$where" = "$host_release" ]; then "$@"; else bash scripts/in_release_root.sh "$where" -- "$@"; fi
}
vk() {   # vk RELEASE FOLDER END [--resume]
    local where="$1" folder="$2" end="$3"; shift 3
    on "$where" env OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_tcp_disable_family=6 \
        mpirun -n 2 .venv/bin/python -m convection run configs/vankeken_1a.yaml --set time.end="$end" \
        --set output.progress=none --output "$folder" "$@"
}
last_vrms() { tail -n 1 "$1/statistics.csv" | cut -d, -f4; }
status=0
for writer in "$host_release" "$other"; do
    if [ "$writer" = "$host_release" ]; then reader="$other"; else reader="$host_release"; fi
    base="output/releases/checkpoint_$writer"
    rm -rf "$base" "${base}_continued"
    vk "$writer" "$base" 60 >/dev/null 2>&1
    cp -r "$base" "${base}_continued"
    vk "$writer" "$base" 120 --resume >/dev/null 2>&1
    vk "$reader" "${base}_continued" 120 --resume 2>"$base.stderr" >/dev/null
    a="$(last_vrms "$base")"; b="$(last_vrms "${base}_continued")"
    "$py" - "$writer" "$reader" "$a" "$b" "$base.stderr" <<'PY' || status=1
import sys
writer, reader, a, b, err = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), open(sys.argv[5]).read()
rel = abs(a - b) / abs(a)
notes = [line for line in err.splitlines() if line.strip()]
print(f"checkpoint of {writer} resumed on {reader}: vrms(t=120) {b!r} against {a!r} on {writer} "
      f"(rel. difference {rel:.1e}); stderr: {notes}")
sys.exit(0 if rel <= 1e-12 and len(notes) == 1 and notes[0].startswith("note: ") else 1)
PY
done
[ "$compare_status" = 0 ] || status=1
exit "$status"
