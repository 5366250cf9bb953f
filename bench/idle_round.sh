#!/bin/bash
# One idle round of every open issue's speed figure (docs/BENCHMARKS.md, the top table), two builds alternated
# inside one command so both see the same machine: BEFORE (a session's start) and AFTER (main after its merges).
# Each is a build directory holding bench/ (bench_stages, bench_probes, bench_rcache). About 6.5 minutes; run it
# with nothing else on the machine, twice.
# usage: bench/idle_round.sh BEFORE_BUILD AFTER_BUILD [SPONZA (../shared/scenes/sponza/sponza.3ds)]
set -euo pipefail
S=$1 M=$2
SP=${3:-../shared/scenes/sponza/sponza.3ds}
cd "$(dirname "$0")/.."
echo "== start $(date -u +%H:%M:%S) load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "== ab_stages"; bench/ab_stages.sh "$S" "$M" 3
echo "== stages whole frame (M S M)"
for b in "$M" "$S" "$M"; do echo "-- $b"; "$b/bench/bench_stages" | sed -n '/whole frame/,$p'; done
echo "== probes overhead (S M S M)"
for b in "$S" "$M" "$S" "$M"; do echo "-- $b"; "$b/bench/bench_probes" --part overhead --scene "$SP"; done
echo "== probes rays (S M S M)"
for b in "$S" "$M" "$S" "$M"; do echo "-- $b"; "$b/bench/bench_probes" --part rays --scene "$SP"; done
echo "== rcache table (S M)"
for b in "$S" "$M"; do echo "-- $b"; "$b/bench/bench_rcache" --only table --reps 3; done
echo "== rcache threads 512 (S M S M S M)"
for b in "$S" "$M" "$S" "$M" "$S" "$M"; do echo "-- $b"; "$b/bench/bench_rcache" --only threads; done
echo "== rcache threads 1024 (S M S M)"
for b in "$S" "$M" "$S" "$M"; do echo "-- $b"; "$b/bench/bench_rcache" --only threads --res 1024 --reps 3; done
echo "== rcache scaling (S M)"; for b in "$S" "$M"; do echo "-- $b"; "$b/bench/bench_rcache" --only scaling; done
echo "== end $(date -u +%H:%M:%S) load $(cut -d' ' -f1-3 /proc/loadavg)"
