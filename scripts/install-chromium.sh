#!/bin/sh
# Installs Debian's Chromium, the headless browser that `tests/viewer_browser.rs` screenshots the
# interactive viewer (`render --export out.html`) with. Idempotent: does nothing when /usr/bin/chromium
# exists. Needs root or sudo, and Debian's package archive (apt-get).
set -eu
if [ -x /usr/bin/chromium ]; then
  echo "chromium: already installed ($(/usr/bin/chromium --version 2>/dev/null || echo /usr/bin/chromium))"
  exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update
$SUDO apt-get install -y --no-install-recommends chromium
/usr/bin/chromium --version
