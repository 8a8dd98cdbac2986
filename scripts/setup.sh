#!/usr/bin/env bash
# Idempotent setup: Debian's DOLFINx 0.5.2 (apt), a venv on top of it, the project in editable mode.
# Usage: scripts/setup.sh   (prints the venv python path on its last line)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"

# Off-screen pictures (pyvista/VTK) need Mesa's EGL and software rasteriser; VTK loads them at run time.
# gmsh meshes the annulus/spherical-shell geometries (convection/mesh.py); Debian's build works with
# DOLFINx 0.5's gmshio, including second-order (curved) cells.
apt_packages=(python3-dolfinx python3-h5py-mpi python3-venv python3-pip python3-yaml python3-scipy python3-gmsh
              libegl1 libegl-mesa0 libgl1-mesa-dri)
if ! /usr/bin/python3 -c "import dolfinx, h5py, yaml, scipy, gmsh" >/dev/null 2>&1 \
        || ! ldconfig -p | grep -q 'libEGL_mesa.so.0'; then
    echo "[setup] installing Debian packages: ${apt_packages[*]}" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q >&2
    apt-get install -y -q "${apt_packages[@]}" >&2
fi

if [ ! -x .venv/bin/python ]; then
    echo "[setup] creating .venv (system site packages)" >&2
    /usr/bin/python3 -m venv --system-site-packages .venv
fi

stamp=.venv/.project-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ requirements/constraints.txt -nt "$stamp" ]; then
    echo "[setup] pip install -e .[test] (numpy pinned to Debian's)" >&2
    .venv/bin/pip install -q -c requirements/constraints.txt -e ".[test]" >&2
    touch "$stamp"
fi
echo "$here/.venv/bin/python"
