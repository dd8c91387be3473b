#!/usr/bin/env bash
# apt-get install the Debian packages listed in scripts/apt-packages.txt that are not installed yet.
# Kept apart from install.sh so the Docker image's apt layer depends on these two files only.
#   APT_CLEAN=1  remove the downloaded .deb files and package lists afterwards (image layers)
set -euo pipefail
list="$(dirname "${BASH_SOURCE[0]}")/apt-packages.txt"
mapfile -t packages < <(sed -e 's/#.*//' -e '/^[[:space:]]*$/d' "$list")
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "install: apt-get installing ${#missing[@]} packages (about 1-2 minutes on a fresh machine): ${missing[*]}"
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
if [ -n "${APT_CLEAN:-}" ]; then
  $SUDO apt-get clean
  $SUDO rm -rf /var/lib/apt/lists/*
fi
