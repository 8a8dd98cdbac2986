#!/usr/bin/env bash
# nsinker side by side with ASPECT 2.5's block GMG in one sitting: every run ROUNDS times, interleaved,
# with the 1-minute load average printed before each run; benchmarks/nsinker/sitting_table.py reads the log
# and keeps the best of the rounds.
#
# Usage (from the repository root; 2 ranks; ONLY=REGEX runs only the cases whose label matches):
#   bash benchmarks/nsinker/sitting.sh [ROUNDS] [CELLS...] | tee benchmarks/nsinker/log/<date>_sitting.txt
#   python -m benchmarks.nsinker.sitting_table benchmarks/nsinker/log/<date>_sitting.txt
#
# ASPECT: ASPECT=path/to/aspect (default /work/aspect-build/aspect, as ../shared/bench/aspect/build.sh
# makes it) and its nsinker plugin NSINKER_PLUGIN=path/to/libnsinker.release.so, built once from ASPECT
# 2.5's benchmarks/nsinker:
#   git --git-dir=ASPECT_GIT_DIR archive v2.5.0 benchmarks/nsinker | tar -x -C DIR
#   cd DIR/benchmarks/nsinker && cmake -DAspect_DIR=ASPECT_BUILD_DIR . && make
#
# The cases, each at DR 1e2 ... 1e6 (4 sinkers, 2 ranks, |b - K x| <= 1e-7 |b| from zero):
# - ASPECT, `Material averaging = harmonic average` (its nsinker_gmg.prm; its GMG needs an averaging);
# - ASPECT, `project to Q1 only viscosity` (the averaging nearest to none that its GMG takes)
#   (at most 300 iterations: it does not converge from DR 1e5 on);
# - ours, material at the quadrature points (averaging none): the multigrid (the defaults: Jacobi
#   smoother, -M_p/eta), the same with w-BFBt (`stokes.schur: wbfbt`) and the SOR multigrid with w-BFBt;
# - ours with ASPECT's harmonic averaging (`--averaging harmonic`): the multigrid with -M_p/eta (the
#   defaults) and the SOR multigrid with w-BFBt.
# Time per solve: ASPECT's "Assemble Stokes system rhs" + "Build Stokes preconditioner" + "Solve Stokes
# system" sections; ours the seconds of StokesSolver.solve (assembly, preconditioner set-up and solve).
# Peak resident size per rank: /usr/bin/time's for ASPECT, getrusage's for ours (both the whole process).
set -uo pipefail
ROUNDS=${1:-3}
shift || true
CELLS=("${@:-8 16}")
read -r -a CELLS <<< "${CELLS[*]}"
PY=${PYTHON:-.venv/bin/python}
ASPECT=${ASPECT:-/work/aspect-build/aspect}
PLUGIN=${NSINKER_PLUGIN:-/work/aspect-nsinker/benchmarks/nsinker/libnsinker.release.so}
RATIOS="1e2 1e3 1e4 1e5 1e6"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
[ -x "$ASPECT" ] && [ -f "$PLUGIN" ] || { echo "no ASPECT ($ASPECT) or nsinker plugin ($PLUGIN): see the header" >&2; exit 2; }
echo "# nsinker sitting: $(nproc) cores, $(date -u +%Y-%m-%dT%H:%MZ), ROUNDS=$ROUNDS CELLS=${CELLS[*]}"

wanted() { [ -z "${ONLY:-}" ] || [[ "$1" =~ $ONLY ]]; }  # ONLY=REGEX: only the cases whose label matches

stamp() { printf '%s load=%s ' "$(date +%H:%M:%S)" "$(cut -d' ' -f1 /proc/loadavg)"; }

aspect_run() {  # CELLS DR AVERAGING MAX_STEPS LABEL
  local n=$1 dr=$2 averaging=$3 steps=$4 label=$5 ref out
  wanted "$label" || return 0
  ref=0; local m=$n; while [ "$m" -gt 1 ]; do m=$(( m / 2 )); ref=$(( ref + 1 )); done
  out="$WORK/aspect-$n-$dr-${averaging// /_}"
  sed -e "s|@TOL@|1e-7|;s|@DR@|$dr|;s|@REF@|$ref|;s|@OUT@|$out|;s|@AVERAGING@|$averaging|;s|@STEPS@|$steps|;s|@PLUGIN@|$PLUGIN|" \
    "$HERE/aspect/nsinker.prm.in" > "$out.prm"
  stamp
  mpirun -n 2 bash -c '/usr/bin/time -f "rss_kb=%M" -o "$0.rss.$OMPI_COMM_WORLD_RANK" "$1" "$0.prm"' "$out" "$ASPECT" \
    > "$out.log" 2>&1
  cat "$out".rss.* >> "$out.log" 2>/dev/null
  "$PY" - "$out.log" "$label" "$n" "$dr" <<'EOF'
import re, sys
text = open(sys.argv[1]).read()
its = re.search(r"Solving Stokes system\.\.\. (\d+)\+(\d+) iterations", text)
sec = lambda name: float(re.search(rf"\| {name} +\| +\d+ \| +([0-9.e+-]+)s", text).group(1)) if re.search(rf"\| {name} ", text) else float("nan")
stokes = sum(sec(s) for s in ("Assemble Stokes system rhs", "Build Stokes preconditioner", "Solve Stokes system"))
rss = max(int(k) for k in re.findall(r"rss_kb=(\d+)", text)) / 1024 if "rss_kb=" in text else float("nan")
vrms = re.search(r"RMS, max velocity: +([0-9.e+-]+)", text)
ok = its is not None and "Solve Stokes system" in text
print(f"{sys.argv[2]}: {sys.argv[3]}^3 DR={float(sys.argv[4]):.0e}: "
      f"{int(its.group(1)) + int(its.group(2)) if its else -1} iterations, {'' if ok else 'unconverged, '}"
      f"{stokes:.3f} s, peak {rss:.0f} MB, vrms {vrms.group(1) if vrms else 'nan'}", flush=True)
EOF
}

ours_run() {  # CELLS AVERAGING LABEL RUN_PY_OPTIONS...
  local n=$1 averaging=$2 label=$3
  shift 3
  wanted "$label" || return 0
  stamp
  echo "$label: all ratios in one process"
  # the first ratio twice: the first solve of a process pays one-time costs (the best of the rounds keeps the warm one)
  mpirun -n 2 "$PY" -m benchmarks.nsinker.run --cells "$n" --ratios 1e2 $RATIOS --solvers multigrid \
    --averaging "$averaging" --out "$WORK/ours" "$@" 2>&1 | grep "DR=" | sed "s/^/$label: /"
}

for r in $(seq "$ROUNDS"); do
  for n in "${CELLS[@]}"; do
    for dr in $RATIOS; do
      aspect_run "$n" "$dr" "harmonic average" 1000 "ASPECT GMG, harmonic"
      aspect_run "$n" "$dr" "project to Q1 only viscosity" 300 "ASPECT GMG, Q1 viscosity"
    done
    ours_run "$n" none "ours MG, none" --schur mass
    ours_run "$n" none "ours MG w-BFBt, none" --schur wbfbt
    ours_run "$n" none "ours SOR-MG w-BFBt, none" --smoother sor --schur wbfbt
    ours_run "$n" harmonic "ours MG, harmonic" --schur mass
    ours_run "$n" harmonic "ours SOR-MG w-BFBt, harmonic" --smoother sor --schur wbfbt
  done
done
