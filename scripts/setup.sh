#!/usr/bin/env bash
# Idempotent setup on whichever Debian this is: Debian's DOLFINx and the rest of the compiled stack
# (apt: DOLFINx 0.5.2 on Debian 12 "bookworm", 0.9.0 on Debian 13 "trixie"), a venv on top of it
# (--system-site-packages), and the project in editable mode with pip pinned to *this* Debian's
# numpy. Fast when nothing changed (no apt, no pip).
#
# PIC_DOLFINX=pypi: the PyPI route instead -- DOLFINx from the binary wheel dolfinx-solver-real
# (0.10/0.11; PETSc inside, MPICH from the `mpich` wheel), h5py (serial: the output gathers to
# rank 0), gmsh, numba, PyYAML and SciPy from PyPI (requirements/pypi.txt), in a venv of Debian's
# Python *without* Debian's site packages. It needs Python >= 3.12 (Debian 13; from a Debian 12
# machine: `PIC_DOLFINX=pypi bash scripts/in_release_root.sh trixie -- bash scripts/setup.sh`).
# apt brings only the C compiler and Python headers (the forms' JIT) and the libraries the gmsh
# and VTK wheels load. Runs on more than one rank use the venv's MPICH launcher (.venv/bin/mpiexec;
# convection/launch.py). The venv remembers its route (.venv/pic-route) and is made again when the
# route changes.
# Usage: [PIC_DOLFINX=debian|pypi] scripts/setup.sh   (prints the venv python path on its last line)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
route="${PIC_DOLFINX:-debian}"
case "$route" in
    debian | pypi) ;;
    *) echo "[setup] PIC_DOLFINX must be 'debian' (Debian's packages, the default) or 'pypi', not '$route'" >&2; exit 2 ;;
esac

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
# time. gmsh meshes the annulus/spherical-shell geometries (convection/geometry/mesh.py). pint reads
# the physical units of configs (convection/physics/scaling.py; 0.19 on 12, 0.24 on 13).
apt_packages=(python3-dolfinx python3-h5py-mpi python3-numba python3-venv python3-pip python3-yaml
              python3-scipy python3-gmsh python3-pint libegl1 libegl-mesa0 libgl1-mesa-dri)
if [ "$route" = pypi ]; then
    # The wheels bring DOLFINx, PETSc, MPICH, h5py, gmsh and numba; Debian gives the Python, the C
    # compiler and headers for the forms' JIT (ffcx + cffi), and the X/GL libraries that the gmsh
    # wheel (built with its GUI) links against and that VTK loads for off-screen pictures.
    apt_packages=(python3-venv python3-dev gcc libc6-dev libglu1-mesa libxcursor1 libxft2 libxinerama1
                  libxrender1 libxext6 libxi6 libsm6 libice6 libfontconfig1 libgomp1
                  libegl1 libegl-mesa0 libgl1-mesa-dri libgl1)
    python_ok="$(/usr/bin/python3 -c 'import sys; print(int(sys.version_info >= (3, 12)))' 2>/dev/null || echo 0)"
    if [ "$python_ok" != 1 ]; then
        echo "[setup] PIC_DOLFINX=pypi needs Python >= 3.12 (the dolfinx-solver-real wheel); Debian" \
             "$debian_version has $(/usr/bin/python3 --version 2>&1). Use Debian 13:" \
             "PIC_DOLFINX=pypi bash scripts/in_release_root.sh trixie -- bash scripts/setup.sh" >&2
        exit 2
    fi
fi
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
venv_route=debian   # a venv made before the PyPI route existed has no .venv/pic-route: Debian's
[ -f .venv/pic-route ] && venv_route="$(cat .venv/pic-route)"
if [ ! -x .venv/bin/python ] || [ "$venv_python" != "$debian_python" ] || [ "$venv_route" != "$route" ]; then
    # --clear: a venv of another Python (the machine was upgraded, or .venv came from elsewhere) or
    # of the other route is emptied and made again; it empties the folder, never removes it (it
    # may be a mount point).
    was="${venv_python:+(was $venv_python, $venv_route)}"
    if [ "$route" = pypi ]; then
        echo "[setup] creating .venv on Debian's Python $debian_python (PyPI route: no system site packages) $was" >&2
        /usr/bin/python3 -m venv --clear .venv
    else
        echo "[setup] creating .venv on Debian's Python $debian_python (system site packages) $was" >&2
        /usr/bin/python3 -m venv --clear --system-site-packages .venv
    fi
    printf '%s\n' "$route" > .venv/pic-route
fi

if [ "$route" = pypi ]; then
    stamp=.venv/.project-installed
    if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ requirements/constraints.txt -nt "$stamp" ] \
            || [ requirements/pypi.txt -nt "$stamp" ]; then
        echo "[setup] pip install -r requirements/pypi.txt -e .[test,docs,lint] (PyPI's DOLFINx)" >&2
        t0=$SECONDS
        .venv/bin/pip install -q -c requirements/constraints.txt -r requirements/pypi.txt -e ".[test,docs,lint]" >&2
        echo "[setup] pip took $((SECONDS - t0)) s" >&2
        # dolfinx_solver (the wheel's loader of its bundled PETSc, MPICH and other libraries) must
        # be imported before dolfinx: a .pth file does it at the start of every Python of this
        # venv, so that `import dolfinx` works anywhere (the code, the tests, scripts, subprocesses).
        site="$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
        printf 'import dolfinx_solver\n' > "$site/pic_dolfinx_solver.pth"
        .venv/bin/python - <<'EOF' >&2
import sys
import dolfinx, h5py, mpi4py.MPI, numpy
bad = []
if not dolfinx.__file__.startswith(sys.prefix):
    bad.append(f"dolfinx from {dolfinx.__file__}, not the venv's")
if "MPICH" not in mpi4py.MPI.Get_library_version():
    bad.append(f"mpi4py's MPI is not MPICH: {mpi4py.MPI.Get_library_version().splitlines()[0]}")
if bad:
    sys.exit("[setup] error: " + "; ".join(bad))
print(f"[setup] DOLFINx {dolfinx.__version__}, numpy {numpy.__version__}, h5py {h5py.__version__}"
      f" (MPI: {h5py.get_config().mpi}), {mpi4py.MPI.Get_library_version().splitlines()[0].strip()}")
EOF
        touch "$stamp"
    fi
    echo "$here/.venv/bin/python"
    exit 0
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
    echo "[setup] pip install -e .[test,docs,lint] (numpy pinned to Debian's $debian_numpy)" >&2
    t0=$SECONDS
    .venv/bin/pip install -q -c "$pins" -c requirements/constraints.txt -e ".[test,docs,lint]" >&2
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
