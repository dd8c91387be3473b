#!/usr/bin/env bash
# apt-get install the Debian packages listed in scripts/apt-packages.txt that are not installed yet.
# Kept apart from install.sh so the Docker image's apt layer depends on these two files only.
#   APT_CLEAN=1  remove the downloaded .deb files and package lists afterwards (image layers)
set -euo pipefail
list="$(dirname "${BASH_SOURCE[0]}")/apt-packages.txt"
# The platform: Debian 12 (bookworm: dolfinx 0.5.2) or Debian 13 (trixie: dolfinx 0.9.0). Both ship
# every package of the list under the same name (checked against both releases' indices), so there is
# one list; a release whose packages differ would get apt-packages-<codename>.txt here.
codename=$(. /etc/os-release 2>/dev/null && echo "${VERSION_CODENAME:-}") || codename=""
case "$codename" in
  bookworm|trixie) ;;
  *) echo "install: this system is ${codename:-not Debian} (apt-packages.txt is for Debian 12 bookworm and" \
          "Debian 13 trixie); install FEniCSx (dolfinx 0.5 or 0.9) yourself and then 'pip install -e .'" \
          "(docs/install.md, \"Your own FEniCSx\")" >&2
     exit 2 ;;
esac
[ -f "${list%.txt}-$codename.txt" ] && list="${list%.txt}-$codename.txt"
mapfile -t packages < <(sed -e 's/#.*//' -e '/^[[:space:]]*$/d' "$list")
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "install: Debian $codename: apt-get installing ${#missing[@]} packages (about 1-2 minutes on a fresh machine): ${missing[*]}"
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
if [ -n "${APT_CLEAN:-}" ]; then
  $SUDO apt-get clean
  $SUDO rm -rf /var/lib/apt/lists/*
fi
