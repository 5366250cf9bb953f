#!/usr/bin/env bash
# The network path's cost: `fxcache serve` over loopback with 1, 4, 8 and 16 fxcache-viewer viewers, and the
# same cameras replayed by `fxcache sim` right after each serve run, so the server-side frame time shows as a
# ratio against the simulator doing the same frames (target: within 10 %).
#
# usage: bench/bench_serve.sh [SCENE] [FRAMES] [COUNTS] [REPEATS]
#   SCENE   default ../shared/scenes/sponza/sponza.3ds
#   FRAMES  frames each viewer receives (default 60; the first 10 are the warm-up, left out)
#   COUNTS  viewer counts (default "1 4 8 16")
#   REPEATS serve/sim pairs per count, alternating (default 2)
# Cameras: the walk generator's first N viewers (recorded once with `fxcache sim --record`), sent by the
# clients at their trace times; the server records what it rendered, and sim replays exactly that.
# Besides the frame times (wall clock, from the statistics both write), the processes' CPU time (user +
# system, GNU time) of serve against sim: less sensitive to other load on a shared machine.
# Prints one table row per count and a codec table (4 viewers); the raw files stay in $BENCH_OUT (default a
# temporary folder, printed).
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:-../shared/scenes/sponza/sponza.3ds}
frames=${2:-60}
counts=${3:-"1 4 8 16"}
repeats=${4:-2}
res=640x360
fps=30
bin=${FXCACHE:-build/server/fxcache}
viewer=${FXCACHE_VIEWER:-build/viewer_client/fxcache-viewer}
out=${BENCH_OUT:-$(mktemp -d /tmp/bench_serve.XXXXXX)}
mkdir -p "$out"
[ "$scene" = default ] || [ -f "$scene" ] || { echo "bench_serve: $scene is missing" >&2; exit 1; }
[ -x "$bin" ] && [ -x "$viewer" ] || { echo "bench_serve: build first (./run demo): $bin, $viewer" >&2; exit 1; }
echo "bench_serve: $scene, $res, $frames frames per viewer, --fps $fps, counts: $counts, $repeats repeats; files in $out"

# The cameras: walkers through the scene (the images are not needed: a tiny resolution). A client sends a
# trace's cameras in real time and stops at its end, so the traces are long (100 s) for the server's frames,
# slower than --fps with many viewers, to reach FRAMES.
max=4 # the codec runs use 4 viewers
for n in $counts; do [ "$n" -gt "$max" ] && max=$n; done
"$bin" sim --scene "$scene" --camera walk --viewers "$max" --frames 3000 --res 16x9 --fps $fps \
  --record "$out/cameras" --quiet --effects shadow >/dev/null

# One serve run: N viewers with codec C; writes $out/$tag.{serve.jsonl,summary.json,client.json} and rec.
serve_run() { # tag n codec
  local tag=$1 n=$2 codec=$3
  rm -rf "$out/$tag.rec"
  /usr/bin/time -f "%e %U %S" -o "$out/$tag.serve.time" \
    "$bin" serve --scene "$scene" --port 0 --fps $fps --quiet --record "$out/$tag.rec" \
    --stats "$out/$tag.serve.jsonl" --summary "$out/$tag.summary.json" >"$out/$tag.serve.out" 2>"$out/$tag.serve.err" &
  local timer=$!
  local pid=""
  for _ in $(seq 1 100); do pid=$(pgrep -P $timer || true); [ -n "$pid" ] && break; sleep 0.05; done
  local port=""
  for _ in $(seq 1 600); do
    port=$(grep -o 'ws://127.0.0.1:[0-9]*' "$out/$tag.serve.out" 2>/dev/null | sed 's/.*://' || true)
    [ -n "$port" ] && break
    sleep 0.1
  done
  [ -n "$port" ] || { echo "bench_serve: serve did not start (see $out/$tag.serve.err)" >&2; kill $pid; wait $timer; exit 1; }
  local traces=()
  for ((v = 0; v < n; v++)); do traces+=(--trace "$out/cameras/$(printf 'viewer_%02u' $v).trace"); done
  "$viewer" --connect "ws://127.0.0.1:$port" --viewers "$n" "${traces[@]}" --res $res --frames "$frames" \
    --codec "$codec" --stats "$out/$tag.client.json" --quiet --timeout 600 >"$out/$tag.client.out" 2>&1 ||
    { echo "bench_serve: a viewer failed (see $out/$tag.client.out)" >&2; kill -TERM $pid; wait $timer; exit 1; }
  kill -TERM $pid
  wait $timer
}

# The same frames in sim: the traces the server recorded.
sim_run() { # tag
  local tag=$1
  local traces=()
  for f in "$out/$tag.rec"/viewer_*.trace; do traces+=(--trace "$f"); done
  /usr/bin/time -f "%e %U %S" -o "$out/$tag.sim.time" \
    "$bin" sim --scene "$scene" "${traces[@]}" --fps $fps --stats "$out/$tag.sim.jsonl" --quiet >/dev/null
}

for n in $counts; do
  for ((r = 0; r < repeats; r++)); do
    serve_run "n$n.r$r" "$n" zstd
    sim_run "n$n.r$r"
  done
done
for codec in raw jpeg; do
  serve_run "codec_$codec" 4 "$codec"
done

python3 bench/bench_serve_report.py "$out" "$counts" "$repeats" "$frames"
