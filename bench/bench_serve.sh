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
[ -f "$scene" ] || { echo "bench_serve: $scene is missing" >&2; exit 1; }
[ -x "$bin" ] && [ -x "$viewer" ] || { echo "bench_serve: build first (./run demo): $bin, $viewer" >&2; exit 1; }
echo "bench_serve: $scene, $res, $frames frames per viewer, --fps $fps, counts: $counts, $repeats repeats; files in $out"

# The cameras: walkers through the scene (the images are not needed: a tiny resolution). A client sends a
# trace's cameras in real time and stops at its end, so the traces are long (100 s) for the server's frames,
# slower than --fps with many viewers, to reach FRAMES.
max=0
for n in $counts; do [ "$n" -gt "$max" ] && max=$n; done
"$bin" sim --scene "$scene" --camera walk --viewers "$max" --frames 3000 --res 16x9 --fps $fps \
  --record "$out/cameras" --quiet --effects shadow >/dev/null

# One serve run: N viewers with codec C; writes $out/$tag.{serve.jsonl,summary.json,client.json} and rec.
serve_run() { # tag n codec
  local tag=$1 n=$2 codec=$3
  rm -rf "$out/$tag.rec"
  "$bin" serve --scene "$scene" --port 0 --fps $fps --quiet --record "$out/$tag.rec" \
    --stats "$out/$tag.serve.jsonl" --summary "$out/$tag.summary.json" >"$out/$tag.serve.out" 2>"$out/$tag.serve.err" &
  local pid=$!
  local port=""
  for _ in $(seq 1 600); do
    port=$(grep -o 'ws://127.0.0.1:[0-9]*' "$out/$tag.serve.out" 2>/dev/null | sed 's/.*://' || true)
    [ -n "$port" ] && break
    sleep 0.1
  done
  [ -n "$port" ] || { echo "bench_serve: serve did not start (see $out/$tag.serve.err)" >&2; kill $pid; exit 1; }
  local traces=()
  for ((v = 0; v < n; v++)); do traces+=(--trace "$out/cameras/$(printf 'viewer_%02u' $v).trace"); done
  "$viewer" --connect "ws://127.0.0.1:$port" --viewers "$n" "${traces[@]}" --res $res --frames "$frames" \
    --codec "$codec" --stats "$out/$tag.client.json" --quiet >"$out/$tag.client.out" 2>&1
  kill -TERM $pid
  wait $pid
}

# The same frames in sim: the traces the server recorded.
sim_run() { # tag
  local tag=$1
  local traces=()
  for f in "$out/$tag.rec"/viewer_*.trace; do traces+=(--trace "$f"); done
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

python3 - "$out" "$counts" "$repeats" "$frames" <<'PY'
import json, statistics, sys
out, counts, repeats, frames = sys.argv[1], sys.argv[2].split(), int(sys.argv[3]), int(sys.argv[4])
warm = 10
def lines(path):
    return [json.loads(l) for l in open(path)]
def stage_times(rows):
    keys = [k for k in rows[0]["time_ms"] if k != "frame"]
    return {k: statistics.median(r["time_ms"][k] for r in rows) for k in keys}
print("\n| viewers | serve ms/frame | sim ms/frame | serve/sim (per repeat) | fps per viewer | latency median | latency p95 | bytes/frame (zstd) |")
print("|---|---|---|---|---|---|---|---|")
for n in counts:
    ratios, serve_ms, sim_ms, fpss, lat50, lat95, bpf = [], [], [], [], [], [], []
    for r in range(repeats):
        tag = f"{out}/n{n}.r{r}"
        se, si = lines(tag + ".serve.jsonl"), lines(tag + ".sim.jsonl")
        # Frames with viewers present in both, after the warm-up: the same frames, same cameras.
        m = min(len(se), len(si))
        se_ms = [x["time_ms"]["frame"] for x in se[warm:m] if x["viewers"]]
        si_ms = [x["time_ms"]["frame"] for x in si[warm:m] if x["viewers"]]
        a, b = statistics.median(se_ms), statistics.median(si_ms)
        serve_ms.append(a); sim_ms.append(b); ratios.append(a / b)
        c = json.load(open(tag + ".client.json"))
        for v in c["viewers"]:
            fpss.append(v["fps"]); lat50.append(v["latency_ms_median"]); lat95.append(v["latency_ms_p95"])
            bpf.append(v["bytes_per_frame"])
    print(f"| {n} | {statistics.median(serve_ms):.1f} | {statistics.median(sim_ms):.1f} | "
          f"{statistics.median(ratios):.3f} ({', '.join(f'{x:.3f}' for x in ratios)}) | {statistics.median(fpss):.1f} | "
          f"{statistics.median(lat50):.0f} ms | {statistics.median(lat95):.0f} ms | {statistics.median(bpf)/1e3:.0f} kB |")
print("\nserver time per stage, median ms per frame (serve, last repeat of each count):")
for n in counts:
    se = lines(f"{out}/n{n}.r{repeats-1}.serve.jsonl")
    st = stage_times([x for x in se[warm:] if x["viewers"]])
    print(f"  {n:>2} viewers: " + ", ".join(f"{k} {v:.1f}" for k, v in st.items()))
print("\n| codec (4 viewers) | bytes per frame | fps per viewer | latency median |")
print("|---|---|---|---|")
for codec, tag in (("raw", "codec_raw"), ("zstd", "n4.r0"), ("jpeg q85", "codec_jpeg")):
    try:
        c = json.load(open(f"{out}/{tag}.client.json"))
    except FileNotFoundError:
        continue
    v = c["viewers"]
    print(f"| {codec} | {statistics.median(x['bytes_per_frame'] for x in v)/1e3:.0f} kB | "
          f"{statistics.median(x['fps'] for x in v):.1f} | {statistics.median(x['latency_ms_median'] for x in v):.0f} ms |")
PY
