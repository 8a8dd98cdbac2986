#!/usr/bin/env bash
# Run a command inside a Debian root of another release (made or reused by scripts/release_root.sh),
# with this repository bind-mounted at the same path and the command started there.
#
# Usage: scripts/in_release_root.sh RELEASE [--] COMMAND [ARGS...]
#   bash scripts/in_release_root.sh trixie -- bash scripts/setup.sh     # DOLFINx 0.9 & co. + venv
#   bash scripts/in_release_root.sh trixie -- bash scripts/test.sh      # the test suite on Debian 13
#   bash scripts/in_release_root.sh trixie -- .venv/bin/python -m convection run configs/vankeken_1a.yaml
#   bash scripts/in_release_root.sh trixie                              # a shell
#   PIC_DOLFINX=pypi bash scripts/in_release_root.sh trixie -- bash scripts/test.sh  # PyPI's DOLFINx
# The command's exit code is this script's.
#
# Inside the root, the repository's .venv is the root's own venv (another Python, another numpy):
# a folder of the root (/var/lib/pic-venvs/<repository path>) is mounted over REPO/.venv for the
# command, so the host's .venv is never touched and every `.venv/bin/python` (scripts, README)
# means the right one on either side. Everything else in the repository (output/, caches) is shared.
#
# Mounts (proc, sys, dev, dev/pts, a private /dev/shm for MPI, the repository, the venv) are made
# in a private mount namespace (unshare) that lives as long as the command: they are gone when it
# ends, however it ends, and never show on the host.
#
# The host's trust and pip configuration (every file named by SSL_CERT_FILE, PIP_CERT,
# REQUESTS_CA_BUNDLE, CURL_CA_BUNDLE, the folder SSL_CERT_DIR, /etc/pip.conf) and /etc/resolv.conf
# are copied into the root at the same paths before each command (apt inside may rewrite them),
# and those variables pass on to the command: pip inside reaches the package index as on the host.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

release="${1:?usage: scripts/in_release_root.sh RELEASE [--] COMMAND [ARGS...]}"
shift
[ "${1:-}" = "--" ] && shift
[ "$#" -eq 0 ] && set -- bash

root="$(bash "$here/scripts/release_root.sh" "$release" | tail -n 1)"
roots="$(dirname "$root")"

# Shared with other commands in this root; scripts/release_root.sh --rebuild waits for it.
exec 9>"$roots/$release.lock"
flock -s 9

# --- the host's trust and pip configuration, at the same paths ---
copy_in() {   # copy_in PATH: a file or a folder of the host to the same path in the root
    local src="$1"
    [ -e "$src" ] || return 0
    if [ -d "$src" ]; then
        mkdir -p "$root$src"
        # -L: the host's /etc/ssl/certs is mostly links into /usr/share/ca-certificates.
        cp -rL --remove-destination "$src/." "$root$src/" 2>/dev/null || cp -rL "$src/." "$root$src/"
    else
        mkdir -p "$root$(dirname "$src")"
        cp -L --remove-destination "$src" "$root$src"
    fi
}
for var in SSL_CERT_FILE PIP_CERT REQUESTS_CA_BUNDLE CURL_CA_BUNDLE SSL_CERT_DIR; do
    [ -n "${!var:-}" ] && copy_in "${!var}"
done
copy_in /etc/pip.conf
copy_in /etc/resolv.conf

# --- the root's own venv for this repository (and route: PIC_DOLFINX=pypi has its own, so that
# switching between Debian's DOLFINx and PyPI's does not remake a venv each time) ---
venv_key="$(printf '%s' "$here" | sed 's|^/||; s|[^A-Za-z0-9._-]|_|g')"
case "${PIC_DOLFINX:-debian}" in
    debian) ;;
    pypi) venv_key="$venv_key+pypi" ;;
    *) echo "in_release_root: PIC_DOLFINX must be debian or pypi, not '$PIC_DOLFINX'" >&2; exit 2 ;;
esac
venv="/var/lib/pic-venvs/$venv_key"
mkdir -p "$root$venv" "$root$here"
mkdir -p "$here/.venv"   # the mount point (an empty folder is what setup.sh makes a venv in anyway)

# --- the command's environment: the host's, less what points at the host's own Python ---
env_args=(-u PYENV_ROOT -u VIRTUAL_ENV -u PYTHONPATH -u PIP_FIND_LINKS
          PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root
          PIC_RELEASE_ROOT="$release")

# shellcheck disable=SC2016
inner='
set -eu
root="$1"; repo="$2"; venv="$3"; shift 3
mount -t proc proc "$root/proc"
mount -t sysfs sysfs "$root/sys"            # hwloc (OpenMPI) reads the topology there
mount --rbind /dev "$root/dev"              # with /dev/pts
mount -t tmpfs -o mode=1777 tmpfs "$root/dev/shm"   # MPI shared memory, the root'"'"'s own
mount --bind "$repo" "$root$repo"
mount --bind "$root$venv" "$root$repo/.venv"
cd /
exec chroot "$root" /bin/sh -c '"'"'cd "$0" && exec "$@"'"'"' "$repo" "$@"
'
rc=0
env "${env_args[@]}" unshare --mount --propagation private \
    bash -c "$inner" bash "$root" "$here" "$venv" "$@" || rc=$?
exit "$rc"
