#!/usr/bin/env bash
# Installs Debian packages where this runs as root with apt-get (the package lists updated
# only when the first try fails); exits non-zero where it could not, and says nothing else.
#   .ci/apt-install.sh PACKAGE...
# Used by .ci/run (in the background, while the code compiles), .ci/blender-check.sh and
# .ci/find-chromium.sh.
set -uo pipefail
[ "$(id -u)" = 0 ] && command -v apt-get >/dev/null || exit 1
export DEBIAN_FRONTEND=noninteractive
apt-get install -y -q "$@" || { apt-get update -q && apt-get install -y -q "$@"; }
