#!/usr/bin/env bash
# Container entry point: `docker run IMAGE run cfg.toml` runs hydrobuckle; a first argument that
# is a program on PATH (mpirun, bash, python, ...) runs that program instead.
set -e
case "${1:-}" in
  ""|-*|run|validate|version|converge|study|sweep|bench|mesh|warmup) exec hydrobuckle "$@" ;;
esac
if command -v "$1" >/dev/null 2>&1; then
  exec "$@"
fi
exec hydrobuckle "$@"
