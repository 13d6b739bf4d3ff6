#!/usr/bin/env bash
# Set up evalharness on a fresh Debian machine. Idempotent: safe to re-run.
#
#   scripts/setup.sh            Debian packages + MuJoCo 3.17.0 + robosuite assets + release build
#   scripts/setup.sh --no-build the same without `cargo build --release`
#   scripts/setup.sh --tests    also Chromium, which the report test screenshots the HTML with
#
# MuJoCo comes from the official `mujoco==3.17.0` wheel on PyPI (Debian ships 2.2.2,
# and mujoco-rs 7.0.0 binds 3.17.0): the wheel is downloaded with pip, checked
# against a pinned sha256 and only `libmujoco.so.3.17.0` is unpacked into
# `.mujoco/lib/` (git-ignored). `.cargo/config.toml` points the build there and
# the binaries carry an rpath to it, so nothing needs exporting.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

build=1
tests=0
for arg in "$@"; do
  case "$arg" in
    --no-build) build=0 ;;
    --tests) tests=1 ;;
    -h|--help) sed -n '2,13p' "$0"; exit 0 ;;
    *) echo "setup.sh: unknown option '$arg'" >&2; exit 2 ;;
  esac
done

MUJOCO_VERSION=3.17.0
WHEEL="mujoco-${MUJOCO_VERSION}-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl"
WHEEL_SHA256=d66928d86a2d1b601bbaa4dc11db50214d17d5301bb8afd84721313b67ff0874
LIBDIR="$root/.mujoco/lib"

say() { printf '\033[1msetup:\033[0m %s\n' "$*" >&2; }

# 1. Debian packages: EGL/Mesa for MuJoCo's offscreen renderer, fonts for plots,
#    pkg-config/unzip/python3-pip for the build and the wheel.
packages=(ca-certificates pkg-config unzip libegl1 libegl-mesa0 libgl1-mesa-dri fonts-dejavu-core)
# pip is only needed when the machine has none already.
command -v python3 >/dev/null 2>&1 || packages+=(python3)
python3 -m pip --version >/dev/null 2>&1 || packages+=(python3-pip)
# Headless Chromium for the HTML report's screenshot test.
[ "$tests" -eq 1 ] && packages+=(chromium)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  say "installing Debian packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# 2. Rust toolchain (burn 0.22 and mujoco-rs 7 need rustc >= 1.95).
if ! command -v cargo >/dev/null 2>&1; then
  echo "setup.sh: cargo not found; install Rust >= 1.95 (https://rustup.rs) and re-run" >&2
  exit 2
fi

# 3. MuJoCo 3.17.0 shared library from the pinned PyPI wheel.
if [ -f "$LIBDIR/libmujoco.so.${MUJOCO_VERSION}" ] && [ -L "$LIBDIR/libmujoco.so" ]; then
  say "MuJoCo ${MUJOCO_VERSION} already in .mujoco/lib"
else
  mkdir -p "$root/.mujoco/wheel" "$LIBDIR"
  if [ ! -f "$root/.mujoco/wheel/$WHEEL" ]; then
    say "downloading mujoco==${MUJOCO_VERSION} wheel from PyPI"
    python3 -m pip download --quiet --no-deps --only-binary=:all: \
      --python-version 3.11 --implementation cp --abi cp311 \
      --platform manylinux_2_28_x86_64 \
      -d "$root/.mujoco/wheel" "mujoco==${MUJOCO_VERSION}"
  fi
  echo "${WHEEL_SHA256}  $root/.mujoco/wheel/$WHEEL" | sha256sum --check --quiet - \
    || { echo "setup.sh: sha256 mismatch for $WHEEL; delete .mujoco/ and re-run" >&2; exit 2; }
  unzip -o -q -j "$root/.mujoco/wheel/$WHEEL" "mujoco/libmujoco.so.${MUJOCO_VERSION}" -d "$LIBDIR"
  ln -sf "libmujoco.so.${MUJOCO_VERSION}" "$LIBDIR/libmujoco.so"
  say "MuJoCo ${MUJOCO_VERSION} unpacked into .mujoco/lib"
fi

# 4. robosuite 1.5.2's scene assets (MIT-licensed) for the Lift and Can scenes:
#    the pinned wheel is checked against its sha256 and only the files the two
#    scenes read are unpacked into .robosuite/assets (git-ignored). No Python
#    package is installed.
RS_VERSION=1.5.2
RS_WHEEL="robosuite-${RS_VERSION}-py3-none-any.whl"
RS_SHA256=b9e02df55de8949739de6ba1d196d2ba59cf33c51a76efcfbe5c2f73cdcf99ce
RS_DIR="$root/.robosuite"
# The stamp names the asset list: a new list re-unpacks.
RS_STAMP="$RS_DIR/assets/.robosuite-${RS_VERSION}-lift-can-2"
if [ -f "$RS_STAMP" ]; then
  say "robosuite ${RS_VERSION} assets already in .robosuite/assets"
else
  mkdir -p "$RS_DIR/wheel"
  if [ ! -f "$RS_DIR/wheel/$RS_WHEEL" ]; then
    say "downloading robosuite==${RS_VERSION} wheel from PyPI"
    python3 -m pip download --quiet --no-deps --only-binary=:all: \
      -d "$RS_DIR/wheel" "robosuite==${RS_VERSION}"
  fi
  echo "${RS_SHA256}  $RS_DIR/wheel/$RS_WHEEL" | sha256sum --check --quiet - \
    || { echo "setup.sh: sha256 mismatch for $RS_WHEEL; delete .robosuite/ and re-run" >&2; exit 2; }
  rm -rf "$RS_DIR/unpack" "$RS_DIR/assets"
  a=robosuite/models/assets
  unzip -q "$RS_DIR/wheel/$RS_WHEEL" -d "$RS_DIR/unpack" \
    "$a/base.xml" "$a/robots/panda/*" "$a/grippers/panda_gripper.xml" \
    "$a/grippers/meshes/panda_gripper/*" "$a/bases/rethink_mount.xml" \
    "$a/bases/meshes/rethink_mount/*" "$a/arenas/table_arena.xml" "$a/arenas/bins_arena.xml" \
    "$a/objects/can.xml" "$a/objects/meshes/can.*" "$a/objects/meshes/milk.stl" \
    "$a/objects/meshes/bread.stl" "$a/objects/meshes/cereal.stl" \
    "$a/textures/light-gray-floor-tile.png" "$a/textures/ceramic.png" \
    "$a/textures/steel-brushed.png" "$a/textures/light-gray-plaster.png" \
    "$a/textures/red-wood.png" "$a/textures/dark-wood.png" "$a/textures/light-wood.png" \
    "$a/textures/soda.png"
  mv "$RS_DIR/unpack/$a" "$RS_DIR/assets"
  rm -rf "$RS_DIR/unpack"
  touch "$RS_STAMP"
  say "robosuite ${RS_VERSION} assets unpacked into .robosuite/assets"
fi

# 5. The release binary.
if [ "$build" -eq 1 ]; then
  say "building target/release/evalharness"
  cargo build --release --locked
fi
say "done"
