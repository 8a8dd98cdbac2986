#!/usr/bin/env bash
# Idempotent setup on whichever Debian this is: Debian's DOLFINx and the rest of the compiled stack
# (apt: DOLFINx 0.5.2 on Debian 12 "bookworm", 0.9.0 on Debian 13 "trixie"), a venv on top of it
# (--system-site-packages), and the project in editable mode with pip pinned to *this* Debian's
# numpy. Fast when nothing changed (no apt, no pip).
# Usage: scripts/setup.sh   (prints the venv python path on its last line)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"

# --- which Debian ---
if [ ! -r /etc/debian_version ]; then
    echo "[setup] this is not Debian (no /etc/debian_version): install DOLFINx, PETSc, mpi4py, h5py (MPI)," \
         "numba and gmsh yourself, then make .venv with --system-site-packages" >&2
    exit 2
fi
codename=""
[ -r /etc/os-release ] && codename="$(. /etc/os-release && echo "${VERSION_CODENAME:-}")"
debian_version="$(cat /etc/debian_version)"
case "$codename" in
    bookworm | trixie) ;;
    *) echo "[setup] warning: Debian '$codename' ($debian_version) is untried; this project is checked on" \
            "bookworm (12, DOLFINx 0.5.2) and trixie (13, DOLFINx 0.9.0)" >&2 ;;
esac

# --- Debian's packages (the same names on 12 and 13) ---
# DOLFINx, PETSc, petsc4py, mpi4py, OpenMPI come with python3-dolfinx; h5py must be Debian's MPI
# build (never pip's, which is serial and would shadow it). numba is Debian's too: it is built
# against Debian's numpy and llvmlite, and its version is the one that supports that numpy
# (0.56.4 with numpy 1.24.2 on 12, 0.61.2 with numpy 2.2.4 on 13); on 12 it comes anyway through
# python3-basix's dependencies, on 13 it must be asked for.
# Off-screen pictures (pyvista/VTK) need Mesa's EGL and software rasteriser; VTK loads them at run
# time. gmsh meshes the annulus/spherical-shell geometries (convection/mesh.py).
apt_packages=(python3-dolfinx python3-h5py-mpi python3-numba python3-venv python3-pip python3-yaml
              python3-scipy python3-gmsh libegl1 libegl-mesa0 libgl1-mesa-dri)
missing=()
for p in "${apt_packages[@]}"; do
    dpkg-query -W -f '${db:Status-Status}' "$p" 2>/dev/null | grep -qx installed || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
    echo "[setup] Debian $debian_version ($codename): installing ${missing[*]}" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q >&2
    t0=$SECONDS
    apt-get install -y -q "${apt_packages[@]}" >&2
    echo "[setup] apt took $((SECONDS - t0)) s" >&2
fi

# --- the venv, on Debian's python ---
debian_python="$(/usr/bin/python3 -c 'import sys; print("%d.%d.%d" % sys.version_info[:3])')"
venv_python=""
[ -f .venv/pyvenv.cfg ] && venv_python="$(sed -n 's/^version *= *//p' .venv/pyvenv.cfg)"
if [ ! -x .venv/bin/python ] || [ "$venv_python" != "$debian_python" ]; then
    # --clear: a venv of another Python (the machine was upgraded, or .venv came from elsewhere) is
    # emptied and made again; it empties the folder, never removes it (it may be a mount point).
    echo "[setup] creating .venv on Debian's Python $debian_python (system site packages)" \
         "${venv_python:+(was $venv_python)}" >&2
    /usr/bin/python3 -m venv --clear --system-site-packages .venv
fi

# --- pip, pinned to this Debian's numpy ---
# An unpinned pip would pull a newer numpy into the venv (pyvista, matplotlib, ...) and break
# petsc4py/dolfinx, which are built against Debian's. The pin is made from Debian's numpy, so it
# follows the release (1.24.2 on 12, 2.2.4 on 13) and any point upgrade; requirements/constraints.txt
# holds the project's other pins, if any.
debian_numpy="$(/usr/bin/python3 -c 'import numpy; print(numpy.__version__)')"
pins=.venv/debian-constraints.txt
want="$(printf '# Made by scripts/setup.sh from Debian %s: pip never replaces these.\nnumpy==%s\n' \
        "$debian_version" "$debian_numpy")"
if [ ! -f "$pins" ] || [ "$(cat "$pins")" != "$want" ]; then
    printf '%s\n' "$want" > "$pins"
fi

stamp=.venv/.project-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ requirements/constraints.txt -nt "$stamp" ] \
        || [ "$pins" -nt "$stamp" ]; then
    echo "[setup] pip install -e .[test] (numpy pinned to Debian's $debian_numpy)" >&2
    t0=$SECONDS
    .venv/bin/pip install -q -c "$pins" -c requirements/constraints.txt -e ".[test]" >&2
    echo "[setup] pip took $((SECONDS - t0)) s" >&2
    # The compiled stack must still be Debian's: numpy (the pin) and h5py (the MPI build).
    .venv/bin/python - "$debian_numpy" <<'EOF' >&2
import sys
import h5py, numpy
bad = []
if numpy.__version__ != sys.argv[1]:
    bad.append(f"numpy {numpy.__version__} from {numpy.__file__}, not Debian's {sys.argv[1]}")
if not h5py.__file__.startswith("/usr/lib/python3/"):
    bad.append(f"h5py from {h5py.__file__}, not Debian's MPI build (python3-h5py-mpi)")
if bad:
    sys.exit("[setup] error: " + "; ".join(bad))
EOF
    touch "$stamp"
fi
echo "$here/.venv/bin/python"
