#!/usr/bin/env bash
# Run a command in this checkout inside a Debian 13 (trixie) root: dolfinx 0.9, PETSc/SLEPc 3.22,
# gmsh 4.13, Python 3.13. The root is built once with debootstrap from the Debian mirror apt already
# uses and kept (with its apt packages and form cache) in $HYDROBUCKLE_DEBIAN13_ROOT, default
# /var/cache/hydrobuckle/debian13, so a repeated run downloads nothing. Needs root.
#   scripts/debian13.sh bash scripts/test.sh       the suite on Debian 13
#   scripts/debian13.sh bash scripts/demo.sh       the demo
# The checkout is bind-mounted at /hydrobuckle; its .venv there is the root's own
# (/opt/hydrobuckle-venv in the root), so it never mixes with this machine's .venv.
# Exit codes: the command's; 75 when the root cannot be built because the mirror is unreachable
# (one line says so). HYDROBUCKLE_DEBIAN_MIRROR=URL builds from another mirror.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
root="${HYDROBUCKLE_DEBIAN13_ROOT:-/var/cache/hydrobuckle/debian13}"
[ "$(id -u)" -eq 0 ] || { echo "debian13: needs root (debootstrap, chroot, mounts)" >&2; exit 2; }
[ $# -gt 0 ] || { echo "usage: scripts/debian13.sh COMMAND [ARG...]" >&2; exit 2; }

# The mirror apt uses on this machine (deb822 or one-line sources), else deb.debian.org.
mirror=$(sed -n 's/^URIs:[[:space:]]*\([^[:space:]]*\/debian\)[[:space:]]*$/\1/p' \
           /etc/apt/sources.list.d/*.sources 2>/dev/null | head -n1)
[ -n "$mirror" ] || mirror=$(awk '$1 == "deb" && $2 ~ /\/debian\/?$/ {print $2; exit}' \
                             /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null || true)
mirror="${HYDROBUCKLE_DEBIAN_MIRROR:-${mirror:-http://deb.debian.org/debian}}"  # the variable: another mirror

# Whether the mirror serves trixie's Release file (within 20 s).
mirror_answers() {
  python3 - "$mirror" 2>/dev/null <<'PY'
import sys, urllib.request
urllib.request.urlopen(sys.argv[1].rstrip("/") + "/dists/trixie/Release", timeout=20).read(64)
PY
}

unreachable() {
  echo "debian13: the Debian mirror $mirror is unreachable ($1); the Debian 13 environment is skipped" >&2
  exit 75
}

if [ ! -e "$root/.hydrobuckle-base" ]; then
  command -v debootstrap >/dev/null || {
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends debootstrap >/dev/null \
      || unreachable "apt-get install debootstrap failed"; }
  mirror_answers || unreachable "no answer from $mirror/dists/trixie/Release"
  echo "debian13: building a minimal trixie root in $root (about 2 minutes, once)"
  rm -rf "$root.part"
  mkdir -p "$(dirname "$root")"
  debootstrap --variant=minbase trixie "$root.part" "$mirror" >"$root.log" 2>&1 \
    || { tail -n 5 "$root.log" >&2; unreachable "debootstrap failed, log $root.log"; }
  rm -rf "$root"
  mv "$root.part" "$root"
  touch "$root/.hydrobuckle-base"
fi

# The mounts live in a mount namespace of this invocation's own (unshare): gone when it ends, and
# invocations running at the same time do not share or undo each other's.
if [ -z "${HYDROBUCKLE_DEBIAN13_NS:-}" ]; then
  HYDROBUCKLE_DEBIAN13_NS=1 exec unshare --mount --propagation private -- bash "${BASH_SOURCE[0]}" "$@"
fi
mount -t proc proc "$root/proc"
for d in dev sys; do
  mount --rbind "/$d" "$root/$d"
done
mkdir -p "$root/hydrobuckle" "$root/opt/hydrobuckle-venv"
mount --bind "$here" "$root/hydrobuckle"
# The checkout's .venv is this machine's; inside the root, .venv is the root's own venv (mounted
# over it in the root only), so the README's commands run unchanged on both.
mkdir -p "$here/.venv"
mount --bind "$root/opt/hydrobuckle-venv" "$root/hydrobuckle/.venv"
cp -L /etc/resolv.conf "$root/etc/resolv.conf" 2>/dev/null || true
# pip in the root (scripts/test-requirements.txt) trusts what this machine trusts: a TLS-inspecting proxy's
# certificate authority may be in this machine's bundle only
pip_cert=()
if [ -f /etc/ssl/certs/ca-certificates.crt ]; then
  cp -L /etc/ssl/certs/ca-certificates.crt "$root/etc/hydrobuckle-host-ca.crt"
  pip_cert=(PIP_CERT=/etc/hydrobuckle-host-ca.crt)
fi

# A clean environment in the root; hydrobuckle's own switches (HYDROBUCKLE_TEST_PARTS, _NO_WARMUP, ...)
# pass through, except the venv (the root has its own) and this script's.
pass=()
while IFS='=' read -r name _; do
  case "$name" in
    HYDROBUCKLE_VENV|HYDROBUCKLE_DEBIAN13_*) ;;
    HYDROBUCKLE_*) pass+=("$name=${!name}") ;;
  esac
done < <(env)
in_root() {
  chroot "$root" /usr/bin/env -i HOME=/root PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    LANG=C.UTF-8 CI="${CI:-}" OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 "${pip_cert[@]}" "${pass[@]}" \
    bash -c 'cd /hydrobuckle && exec "$@"' debian13 "$@"
}

# The system packages (scripts/apt-packages.txt): quick when they are there already. When apt cannot
# fetch them because the mirror is unreachable, the environment cannot be built: exit 75.
if ! in_root bash scripts/apt-install.sh; then
  mirror_answers || unreachable "apt-get could not fetch the packages"
  echo "debian13: apt-get install of scripts/apt-packages.txt failed in $root" >&2
  exit 1
fi

in_root "$@"
