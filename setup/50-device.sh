#!/usr/bin/env bash
# The C device side (astcom_device/): Debian's compiler and C libraries for the host build
# and its tests, the Cortex-M4 toolchain and QEMU for the firmware, socat for pty pairs.
#   host:  gcc make libmpack-dev (read msgpack) libmsgpack-dev (write msgpack)
#          libmbedtls-dev (HMAC-SHA256) socat
#   MCU:   gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm, and the Debian source
#          packages of libmpack and mbedtls (unpacked under astcom_device/build/deb-src/,
#          never committed), compiled for the Cortex-M4 by astcom_device/port/stm32/firmware.mk.
# Idempotent and quick when everything is there.
set -euo pipefail
. "$(dirname "$0")/lib/apt.bash"
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
PACKAGES="gcc make libc6-dev libmpack-dev libmsgpack-dev libmbedtls-dev socat gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm"

have_all() {
    command -v gcc >/dev/null && command -v socat >/dev/null \
        && command -v arm-none-eabi-gcc >/dev/null && command -v qemu-system-arm >/dev/null \
        && [ -f /usr/include/mpack.h ] && [ -f /usr/include/msgpack.h ] \
        && [ -f /usr/include/mbedtls/md.h ] && [ -f /usr/lib/arm-none-eabi/include/string.h ]
}

install_all() {
    # shellcheck disable=SC2086
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends $PACKAGES
}

if have_all; then
    echo "C device toolchain already installed"
else
    need_apt setup/50-device.sh "$PACKAGES" "the C device tests will fail"
    apt_install setup/50-device.sh "$PACKAGES" install_all
fi

# Debian's sources of libmpack and mbedtls, for the firmware (the host links the packages).
SRC="$ROOT/astcom_device/build/deb-src"
if [ -d "$SRC/libmpack" ] && [ -d "$SRC/mbedtls" ]; then
    echo "Debian sources of libmpack and mbedtls already unpacked in $SRC"
    exit 0
fi
mkdir -p "$SRC/apt/lists/partial" "$SRC/apt/parts"
cat > "$SRC/apt/parts/debian-src.sources" <<'EOF'
Types: deb-src
URIs: http://deb.debian.org/debian
Suites: bookworm
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
# a private source list and package lists: the machine's apt configuration is not touched
APT=(-o "Dir::Etc::SourceList=/dev/null" -o "Dir::Etc::SourceParts=$SRC/apt/parts"
     -o "Dir::State::Lists=$SRC/apt/lists" -o "APT::Sandbox::User=root")
apt-get "${APT[@]}" update -q >/dev/null
cd "$SRC"
# --tar-only: the upstream tarball, checked against the hash in Debian's signed index
apt-get "${APT[@]}" source --download-only --tar-only libmpack mbedtls
for pkg in libmpack mbedtls; do
    tarball=$(ls ${pkg}_*.orig.tar.* | head -1)
    mkdir -p "$pkg"
    tar -xf "$tarball" -C "$pkg" --strip-components=1
done
echo "Debian sources unpacked in $SRC"
