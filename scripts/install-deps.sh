#!/usr/bin/env bash
# Installs the Debian 12 packages this project builds and tests with. Idempotent: packages already
# present are left alone, and apt is not touched at all when nothing is missing. Run as root.
set -euo pipefail

packages=(
  g++ cmake make pkg-config
  libeigen3-dev            # dense/sparse linear algebra
  libsuitesparse-dev       # CHOLMOD sparse Cholesky (solver)
  libopenblas-dev          # BLAS/LAPACK behind CHOLMOD
  libgmsh-dev              # tetrahedralization, CAD import (OpenCASCADE), .msh I/O
  libcli11-dev             # command-line parsing
  libspdlog-dev libfmt-dev # CLI logging
  nlohmann-json3-dev       # report.json
  libgtest-dev             # tests
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

if [ "$(id -u)" -ne 0 ]; then
  echo "install-deps: missing packages: ${missing[*]}; run this script as root (or install them with apt-get)" >&2
  exit 1
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -q
apt-get install -y -q --no-install-recommends "${missing[@]}"
