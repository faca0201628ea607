#!/usr/bin/env bash
# The Debian trixie chroot in which `make test-gui` runs a real Blender (4.3.2, Debian's package)
# under Xvfb. Built once and cached outside the repository; reused while its stamp matches.
#
#   tools/gui_chroot.sh ensure          # build the chroot if missing (needs root + Debian's mirror)
#   tools/gui_chroot.sh mount|umount    # bind /dev, /dev/pts, /proc, /sys (umount is idempotent)
#   tools/gui_chroot.sh check           # exit 0 if a build is possible here (root, debootstrap or
#                                       # apt, mirror reachable), else print why and exit 3
#
# RELIGHT_GUI_ROOT (default /var/cache/relight-gui/trixie) chooses the directory.
# No python3-scipy in the chroot: the extension's bundled wheels are what gets tested.
set -euo pipefail
ROOT="${RELIGHT_GUI_ROOT:-/var/cache/relight-gui/trixie}"
MIRROR="${RELIGHT_GUI_MIRROR:-http://deb.debian.org/debian}"
PACKAGES="blender xvfb xauth x11-apps imagemagick xdotool libgl1-mesa-dri libglx-mesa0 mesa-utils python3-numpy"
STAMP="$ROOT/.relight-gui-chroot-$(echo "$PACKAGES" | cksum | cut -d' ' -f1)"

mounts() { echo dev dev/pts proc sys; }

do_mount() {
    for d in $(mounts); do
        mountpoint -q "$ROOT/$d" || mount --bind "/$d" "$ROOT/$d"
    done
    cp /etc/resolv.conf "$ROOT/etc/resolv.conf" 2>/dev/null || true
}

do_umount() {
    for d in sys proc dev/pts dev; do
        if mountpoint -q "$ROOT/$d" 2>/dev/null; then umount "$ROOT/$d" || umount -l "$ROOT/$d"; fi
    done
}

check() {
    if [ "$(id -u)" != 0 ]; then echo "needs root (chroot, mount)"; return 3; fi
    if [ -e "$STAMP" ]; then return 0; fi
    if ! command -v debootstrap >/dev/null && ! command -v apt-get >/dev/null; then
        echo "no debootstrap and no apt-get to install it"; return 3
    fi
    if ! timeout 20 bash -c "exec 3<>/dev/tcp/$(echo "$MIRROR" | sed -E 's#^[a-z]+://([^/:]+).*#\1#')/80" 2>/dev/null; then
        echo "Debian's mirror $MIRROR is not reachable"; return 3
    fi
    return 0
}

ensure() {
    if [ -e "$STAMP" ]; then echo "gui chroot: cached at $ROOT"; return 0; fi
    check || exit $?
    command -v debootstrap >/dev/null || { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap; }
    local t0=$SECONDS
    trap do_umount EXIT
    if [ ! -x "$ROOT/usr/bin/apt-get" ]; then
        rm -rf "$ROOT"; mkdir -p "$(dirname "$ROOT")"
        debootstrap --variant=minbase trixie "$ROOT" "$MIRROR"
    fi
    do_mount
    chroot "$ROOT" bash -c "export DEBIAN_FRONTEND=noninteractive; apt-get update -qq && \
        apt-get install -y -qq --no-install-recommends $PACKAGES && apt-get clean"
    if chroot "$ROOT" python3 -c "import scipy" 2>/dev/null; then
        echo "gui chroot: python3-scipy is installed; remove it so the bundled wheels are tested" >&2; exit 1
    fi
    chroot "$ROOT" blender --version | head -1
    do_umount; trap - EXIT
    rm -f "$ROOT"/.relight-gui-chroot-*; touch "$STAMP"
    echo "gui chroot: built $ROOT in $((SECONDS - t0)) s"
}

case "${1:-}" in
    ensure) ensure ;;
    mount) do_mount ;;
    umount) do_umount ;;
    check) check ;;
    root) echo "$ROOT" ;;
    *) echo "usage: $0 ensure|mount|umount|check|root" >&2; exit 2 ;;
esac
