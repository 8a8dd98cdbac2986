#!/usr/bin/env bash
# Make (or reuse) a Debian root of another release to run this project on, e.g. Debian 13 "trixie"
# with DOLFINx 0.9 from a Debian 12 machine (DOLFINx 0.5.2).
#
# Usage: scripts/release_root.sh RELEASE          (prints the root's path on its last line)
#        scripts/release_root.sh RELEASE --rebuild (delete the cached root first)
#
# The root is a debootstrap --variant=minbase of RELEASE (any Debian codename the host's
# debootstrap knows: trixie, bookworm, sid, ...) with its -updates and -security suites, kept under
# ${PIC_ROOTS:-/var/cache/pic-convection}/RELEASE and reused by later calls (a fresh one in CI:
# scripts/ci_release.sh sets PIC_ROOTS to a new folder). It holds only the base system: the
# project's own packages (python3-dolfinx & co.) are installed by scripts/setup.sh run inside
# (scripts/in_release_root.sh RELEASE -- bash scripts/setup.sh), the same script that sets up the
# host, and they stay in the cached root for the next time.
#
# Nothing stays mounted: debootstrap runs in a private mount namespace (unshare), so even a killed
# run leaves no mount behind; scripts/in_release_root.sh does the same for the commands it runs.
set -euo pipefail

release="${1:?usage: scripts/release_root.sh RELEASE [--rebuild]}"
rebuild=0
[ "${2:-}" = "--rebuild" ] && rebuild=1
case "$release" in
    *[!a-z0-9-]* | "") echo "release_root: not a Debian codename: '$release'" >&2; exit 2 ;;
esac
if [ "$(id -u)" != 0 ]; then echo "release_root: needs root (debootstrap, chroot, mount)" >&2; exit 2; fi

roots="${PIC_ROOTS:-/var/cache/pic-convection}"
root="$roots/$release"
mirror="${PIC_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
security_mirror="${PIC_DEBIAN_SECURITY_MIRROR:-http://deb.debian.org/debian-security}"
stamp=".pic-release-root"   # written last: a root without it is unfinished and made again
mkdir -p "$roots"

# True if anything is mounted at or below $1 (then it must not be deleted: a bind mount below it
# would take the host's files with it).
mounted_below() {
    awk -v p="$1" '{ m = $5; gsub(/\\040/, " ", m); if (m == p || index(m, p "/") == 1) found = 1 } END { exit !found }' /proc/self/mountinfo
}
remove_root() {
    if mounted_below "$1"; then
        echo "release_root: something is mounted under $1; not deleting it (see: findmnt -R $1)" >&2
        exit 1
    fi
    rm -rf --one-file-system "$1"
}

# One maker at a time per release; scripts/in_release_root.sh holds the same lock shared while a
# command runs, so a --rebuild waits for running commands instead of deleting their root. A root
# that is there already is only looked at (shared lock): commands in it may run side by side.
exec 9>"$roots/$release.lock"
flock -s 9
if [ "$rebuild" = 0 ] && [ -f "$root/$stamp" ]; then
    echo "$root"
    exit 0
fi
flock -u 9
if ! flock -n 9; then
    echo "release_root: waiting for the commands running in $root to finish" >&2
    flock 9
fi

if [ "$rebuild" = 1 ] && [ -e "$root" ]; then
    echo "release_root: deleting $root (--rebuild)" >&2
    remove_root "$root"
fi

if [ ! -f "$root/$stamp" ]; then
    if ! command -v debootstrap >/dev/null 2>&1; then
        echo "release_root: installing debootstrap" >&2
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -q >&2
        apt-get install -y -q debootstrap >&2
    fi
    if [ ! -e "/usr/share/debootstrap/scripts/$release" ]; then
        echo "release_root: this debootstrap does not know '$release'" >&2; exit 2
    fi
    partial="$root.partial"
    [ -e "$partial" ] && remove_root "$partial"
    [ -e "$root" ] && remove_root "$root"   # an unfinished root from an older run
    echo "release_root: debootstrap --variant=minbase $release $partial ($mirror)" >&2
    t0=$SECONDS
    # debootstrap mounts /proc and /sys in the target while it works: a private mount namespace
    # makes sure they go away even if it is killed.
    unshare --mount --propagation private \
        debootstrap --variant=minbase "$release" "$partial" "$mirror" >&2
    echo "release_root: debootstrap took $((SECONDS - t0)) s" >&2

    # The suites a real machine of this release has: updates and security fixes too (sid has none).
    suites="$release"
    if [ "$release" != sid ] && [ "$release" != unstable ]; then suites="$release $release-updates"; fi
    {
        printf 'Types: deb\nURIs: %s\nSuites: %s\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
            "$mirror" "$suites"
        if [ "$release" != sid ] && [ "$release" != unstable ]; then
            printf '\nTypes: deb\nURIs: %s\nSuites: %s-security\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
                "$security_mirror" "$release"
        fi
    } > "$partial/etc/apt/sources.list.d/debian.sources"
    : > "$partial/etc/apt/sources.list"
    # No services start inside the root when packages are installed.
    printf '#!/bin/sh\nexit 101\n' > "$partial/usr/sbin/policy-rc.d"
    chmod 755 "$partial/usr/sbin/policy-rc.d"
    # Mark it as a chroot of this project (shown by scripts/in_release_root.sh).
    printf 'release=%s\nmade=%s\ndebootstrap=%s\nmirror=%s\n' "$release" "$(date -u +%FT%TZ)" \
        "$(dpkg-query -W -f '${Version}' debootstrap 2>/dev/null || echo '?')" "$mirror" > "$partial/$stamp"
    mv "$partial" "$root"
fi
echo "$root"
