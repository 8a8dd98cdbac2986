# Shared by the sitting scripts (sourced): the vortex problem of the sittings, the filter that
# prints a run's rate, and `run LABEL CMD...`, which prints the time, the 1-minute load average
# and the label before the command's own line.
V="-m benchmarks.performance.vortex --cells 64 --particles 393216 --steps 50"
RATE='import json,sys; print("rate=%.0f" % json.loads([l for l in sys.stdin if l.startswith("{")][-1])["particle_updates_per_second"])'
run() {
  local label=$1; shift
  printf '%s load=%s %-40s ' "$(date +%H:%M:%S)" "$(cut -d' ' -f1 /proc/loadavg)" "$label"
  "$@"
}
