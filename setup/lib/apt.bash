# Shared by the setup/*.sh scripts that install a Debian package; sourced, never run by
# itself (make runs setup/*.sh only).

# need_apt SCRIPT PACKAGE HINT: return when apt-get can install PACKAGE here (root, or sudo,
# in $SUDO); otherwise say what to do (HINT: what happens without it) and exit 0, so that
# the rest of the set-up goes on.
need_apt() {
    local script=$1 package=$2 hint=$3
    if ! command -v apt-get >/dev/null 2>&1; then
        echo "$script: apt-get not found; install the $package package by hand, or $hint" >&2
        exit 0
    fi
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then
        if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
            echo "$script: not root and no sudo; install the $package package by hand, or $hint" >&2
            exit 0
        fi
    fi
}

apt_get_install() {
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "$1"
}

# apt_install SCRIPT PACKAGE [INSTALLER]: install PACKAGE (INSTALLER: a function taking the
# package, default apt_get_install); if that fails, refresh the package lists once and retry.
apt_install() {
    local script=$1 package=$2 installer=${3:-apt_get_install}
    if ! "$installer" "$package"; then
        echo "$script: install failed; refreshing package lists once and retrying"
        $SUDO apt-get update -q
        "$installer" "$package"
    fi
}
