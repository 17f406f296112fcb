#!/usr/bin/env bash
# Installs every Debian 12 package the project needs to build, run and test (idempotent).
# Run as root, or as a user with sudo. Usage: deploy/install-deps.sh
set -euo pipefail

PACKAGES=(
  # toolchain
  build-essential cmake pkg-config ccache
  # design-card packages
  libusb-1.0-0-dev libhidapi-dev libglm-dev libopenmesh-dev libegl-dev libgles-dev libegl-mesa0
  libgl1-mesa-dri libdraco-dev libtinygltf-dev
  # display frames (PNG) and the scene's base-colour textures (PNG, JPEG)
  libpng-dev libjpeg-dev
  # the text printed on display frames (stb_easy_font, header only)
  libstb-dev
  # the display's window (GLFW) and its test under Xvfb
  libglfw3-dev xvfb xauth libx11-dev
  # libraries the build uses
  libccd-dev libeigen3-dev nlohmann-json3-dev libcli11-dev libsodium-dev
  # the CPU texture stage's thread pool
  libtbb-dev
  # haptic model build: convex hulls (qhull) and the texture bake's ray casting (Embree 3)
  libqhull-dev libembree-dev
  # FCL: the reference the coarse contact query is checked and benchmarked against
  libfcl-dev
  # zlib: the depth maps' deflate (codecs); meshoptimizer: what the scene stream's Draco is
  # compared with
  libmeshoptimizer-dev zlib1g-dev
  # tests and benchmarks; clang's libFuzzer for the datagram fuzz target; iproute2 for the
  # network-namespace split test
  libgtest-dev libgmock-dev libbenchmark-dev clang libclang-rt-14-dev iproute2
  # plots of the speed-vs-error frontier (deploy/plot-frontier runs /usr/bin/python3)
  python3-matplotlib
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages already installed"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "install-deps: need root or sudo to install: ${missing[*]}" >&2
    exit 1
  fi
fi
echo "install-deps: installing ${#missing[@]} package(s): ${missing[*]}"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "install-deps: done"
