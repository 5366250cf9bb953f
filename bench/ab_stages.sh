#!/usr/bin/env bash
# Alternates two builds of bench_stages (before, after) inside one command, so both see the same machine:
# prints, per round, each build's median requests / visibility and compose / visibility (part 1 only).
# usage: bench/ab_stages.sh BEFORE_BUILD_DIR AFTER_BUILD_DIR [ROUNDS (3)] [bench_stages options...]
set -euo pipefail
before=$1 after=$2 rounds=${3:-3}
shift $(( $# >= 3 ? 3 : 2 ))
echo "| round | build | requests / visibility | compose / visibility |"
echo "|---|---|---|---|"
for round in $(seq 1 "$rounds"); do
  for build in "$before" "$after"; do
    out=$("$build/bench/bench_stages" --no-scaling "$@")
    req=$(echo "$out" | awk -F'|' '/requests \/ visibility/ {gsub(/ /, "", $3); print $3}')
    comp=$(echo "$out" | awk -F'|' '/compose \/ visibility/ {gsub(/ /, "", $3); print $3}')
    echo "| $round | $build | $req | $comp |"
  done
done
