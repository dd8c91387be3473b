#!/usr/bin/env bash
# Build the hydrobuckle Docker images (debian:trixie, the default, and debian:bookworm) and check the
# docker commands of docs/install.md on each (minutes; not in .ci/run).
#   bash scripts/docker-check.sh [--tests] [--keep-daemon] [--release=trixie|bookworm]
# - installs docker.io and debootstrap if missing (apt-get, needs root);
# - starts dockerd if no daemon answers, and stops only that daemon (by its PID) at the end;
# - uses debian:trixie / debian:bookworm if present or pullable, else builds them with debootstrap
#   (minbase) from the Debian mirror this machine's apt uses and imports them;
# - tags hydrobuckle:trixie, hydrobuckle:bookworm, and hydrobuckle = hydrobuckle:trixie;
# - builds the image, runs `version`, docs/install.md's `mpirun -n 2 hydrobuckle run` on a small mesh as
#   root and as a non-root --user with a mounted result directory, and fails on: missing console
#   script, Open MPI "Read -1, expected" noise, a non-writable cache, an image over its size limit (2.9 GB on Debian 13, 2.5 GB on 12), a
#   result not "buckled";
# - with --tests, also runs the test suite (serial and 2 ranks) inside the image.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
run_tests=0; keep=0; releases=(trixie bookworm)
for a in "$@"; do
  case "$a" in
    --tests) run_tests=1 ;;
    --keep-daemon) keep=1 ;;
    --release=trixie|--release=bookworm) releases=("${a#--release=}") ;;
    *) echo "docker-check: unknown option $a (allowed: --tests, --keep-daemon, --release=trixie|bookworm)" >&2; exit 2 ;;
  esac
done
image_name="${HYDROBUCKLE_IMAGE:-hydrobuckle}"
work="$(mktemp -d)"
daemon_pid=""
cleanup() {
  if [ -n "$daemon_pid" ] && [ "$keep" -eq 0 ]; then
    echo "docker-check: stopping the dockerd this script started (pid $daemon_pid)"
    kill "$daemon_pid" 2>/dev/null || true
    for _ in $(seq 30); do kill -0 "$daemon_pid" 2>/dev/null || break; sleep 1; done
  fi
  rm -rf "$work"
}
trap cleanup EXIT
step() { echo; echo "== $* ($(date +%T))"; }
seconds() { local t0=$1; echo $(( $(date +%s) - t0 )); }

need=()
{ command -v docker && command -v dockerd; } >/dev/null || need+=(docker.io)  # a docker client alone is not enough
command -v debootstrap >/dev/null || need+=(debootstrap)
if [ ${#need[@]} -gt 0 ]; then
  step "apt-get install ${need[*]}"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need[@]}"
fi

if ! docker info >/dev/null 2>&1; then
  step "starting dockerd"
  dockerd >"$work/dockerd.log" 2>&1 &
  daemon_pid=$!
  for _ in $(seq 60); do docker info >/dev/null 2>&1 && break; sleep 1; done
  docker info >/dev/null 2>&1 || { echo "docker-check: dockerd did not start:"; tail -20 "$work/dockerd.log"; exit 1; }
fi

make_base() {  # $1: codename; debian:$1 pulled, or built with debootstrap (minbase) and imported
  local codename=$1
  docker image inspect "debian:$codename" >/dev/null 2>&1 && return 0
  step "base image debian:$codename"
  timeout 60 docker pull "debian:$codename" >/dev/null 2>&1 && return 0
  local t0; t0=$(date +%s)
  local mirror
  mirror=$(awk '/^URIs:/ && $2 ~ /\/debian\/?$/ {print $2; exit}' /etc/apt/sources.list.d/*.sources 2>/dev/null || true)
  [ -n "$mirror" ] || mirror=$(awk '$1 == "deb" && $2 ~ /\/debian\/?$/ {print $2; exit}' /etc/apt/sources.list 2>/dev/null || true)
  [ -n "$mirror" ] || mirror="http://deb.debian.org/debian"
  echo "docker-check: cannot pull; debootstrap --variant=minbase $codename from $mirror"
  rm -rf "$work/rootfs"
  debootstrap --variant=minbase "$codename" "$work/rootfs" "$mirror" >"$work/debootstrap.log" 2>&1 \
    || { tail -20 "$work/debootstrap.log"; exit 1; }
  # the same suites as the host's apt (updates, security), renamed to this release
  local host_codename; host_codename=$(. /etc/os-release && echo "$VERSION_CODENAME")
  if [ -f /etc/apt/sources.list.d/debian.sources ]; then
    sed "s/\b$host_codename\b/$codename/g" /etc/apt/sources.list.d/debian.sources \
      >"$work/rootfs/etc/apt/sources.list.d/debian.sources"
    rm -f "$work/rootfs/etc/apt/sources.list"
  fi
  rm -rf "$work/rootfs/var/cache/apt/archives/"*.deb "$work/rootfs/var/lib/apt/lists/"*
  tar -C "$work/rootfs" -c . | docker import - "debian:$codename" >/dev/null
  rm -rf "$work/rootfs"
  echo "docker-check: base image debian:$codename imported in $(seconds "$t0") s"
}

check_image() {  # $1: codename, $2: the dolfinx version its image must report, $3: its size limit (MB)
  local codename=$1 want=$2 limit=$3
  local image="$image_name:$codename"
  make_base "$codename"
  step "docker build --build-arg BASE=debian:$codename -t $image ."
  local t0; t0=$(date +%s)
  docker build --build-arg "BASE=debian:$codename" -t "$image" . 2>&1 | tee "$work/build.log" | grep -E '^(Step|#[0-9]+ \[|Successfully)|warmup:|install:' || true
  [ "${PIPESTATUS[0]}" -eq 0 ] || { tail -30 "$work/build.log"; exit 1; }
  echo "docker-check: build $(seconds "$t0") s"
  local size; size=$(docker image inspect "$image" --format '{{.Size}}')
  echo "docker-check: image size $(( size / 1000000 )) MB"
  [ "$size" -lt $(( limit * 1000000 )) ] || { echo "docker-check: FAIL image larger than $limit MB"; exit 1; }

  step "docker run --rm $image version"
  docker run --rm "$image" version | tee "$work/version.txt"
  grep -q "^dolfinx $want" "$work/version.txt" || { echo "docker-check: FAIL version"; exit 1; }

  small=(--set mesh.element_size=0.02 --set mesh.film_layers=2 --set geometry.length=0.4
         --set geometry.substrate_thickness=0.2 --set stability.error_estimate=false --set output.every=2)
  check_run() {  # $1: label, $2: result dir on the host, rest: docker run options
    local label=$1 dir=$2; shift 2
    local t0; t0=$(date +%s)
    docker run --rm "$@" -v "$dir:/opt/hydrobuckle/results" "$image" \
      mpirun -n 2 hydrobuckle run configs/bilayer.toml "${small[@]}" >"$work/$label.log" 2>&1 \
      || { echo "docker-check: FAIL ($label) exit $?"; tail -20 "$work/$label.log"; exit 1; }
    local secs; secs=$(seconds "$t0")
    if grep -q "Read -1, expected" "$work/$label.log"; then
      echo "docker-check: FAIL ($label) Open MPI single-copy noise: $(grep -c 'Read -1' "$work/$label.log") lines"; exit 1
    fi
    if grep -qi "permission denied" "$work/$label.log"; then
      echo "docker-check: FAIL ($label) permission denied:"; grep -i "permission denied" "$work/$label.log" | head -3; exit 1
    fi
    local status; status=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['status'])" \
      "$dir/bilayer/summary.json")
    [ "$status" = "buckled" ] || { echo "docker-check: FAIL ($label) status $status"; exit 1; }
    echo "docker-check: ($label) mpirun -n 2 hydrobuckle run ok in $secs s: $(grep 'critical growth' "$work/$label.log" | sed 's/.*hydrobuckle: //')"
    echo "docker-check: ($label) result files owned by $(stat -c %u:%g "$dir/bilayer/summary.json")"
  }

  step "docker run (root) mpirun -n 2 hydrobuckle run configs/bilayer.toml (small mesh)"
  mkdir -p "$work/results-root-$codename"
  check_run "root-$codename" "$work/results-root-$codename"

  step "docker run --user 1000:1000 (a non-root user) with a mounted result directory"
  mkdir -p "$work/results-user-$codename" && chown 1000:1000 "$work/results-user-$codename"
  check_run "user-$codename" "$work/results-user-$codename" --user 1000:1000
  [ "$(stat -c %u "$work/results-user-$codename/bilayer/summary.json")" = "1000" ] \
    || { echo "docker-check: FAIL result files not owned by the --user uid"; exit 1; }

  if [ "$run_tests" -eq 1 ]; then
    step "test suite inside $image (serial and 2 ranks)"
    t0=$(date +%s)
    docker run --rm "$image" bash scripts/test.sh >"$work/tests-$codename.log" 2>&1 \
      || { echo "docker-check: FAIL tests"; tail -40 "$work/tests-$codename.log"; exit 1; }
    grep -E "passed|failed" "$work/tests-$codename.log" | tail -2
    echo "docker-check: tests $(seconds "$t0") s"
  fi
  echo "docker-check: $image ($codename, dolfinx $want) passed"
}

for codename in "${releases[@]}"; do
  case "$codename" in
    # limits: the measured size plus 10% (Debian 13's FEniCSx packages alone are 0.4 GB more)
    trixie) check_image trixie 0.9 2900 ;;
    bookworm) check_image bookworm 0.5 2500 ;;
  esac
done
# the default tag is the default build (Debian 13)
if docker image inspect "$image_name:trixie" >/dev/null 2>&1; then docker tag "$image_name:trixie" "$image_name"; fi
echo
echo "docker-check: all checks passed"
