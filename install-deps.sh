#!/usr/bin/env bash
# Installs the Debian packages fxcache needs, and only those that are missing.
# Idempotent: prints what it installs, and nothing but one line when everything is already there.
set -euo pipefail

packages=(
  build-essential cmake pkg-config g++
  libembree-dev libtbb-dev
  libassimp-dev
  libopenmesh-dev
  libopenimageio-dev
  libjansson-dev
  zlib1g-dev libzstd-dev libturbojpeg0-dev
  clang libclang-rt-14-dev clang-format
  libwebsockets-dev
  libcmocka-dev
  nodejs node-ws zstd
  time
  gnuplot-nox
  uthash-dev libglib2.0-dev
  glmark2-data
  assimp-testmodels
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${missing[*]}"
sudo=""
if [ "$(id -u)" -ne 0 ]; then
  sudo="sudo"
fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install-deps: done"
