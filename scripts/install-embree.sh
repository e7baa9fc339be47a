#!/bin/sh
# Installs the Embree 3 system library needed by `cargo build --features embree` (Debian/Ubuntu).
set -eu
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
$SUDO apt-get update
$SUDO apt-get install -y libembree-dev
