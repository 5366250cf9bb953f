#!/usr/bin/env bash
# Runs the fxcache sim benchmarks of docs/BENCHMARKS.md and prints markdown tables:
#   1. viewers 1, 2, 4, 8 walking through the same scene: requested vs unique texels, effect rays per frame,
#      memory, frame time per stage, and the marginal cost of each added viewer;
#   2. effect rays per frame in steady state (a static view) against --no-cache for the same frames;
#   3. memory at AO and shadow level bias 0 and 2.
# usage: bench/sim_sweep.sh [SCENE] [FRAMES]   (default: ../shared/scenes/sponza/sponza.3ds, 20 frames)
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:-../shared/scenes/sponza/sponza.3ds}
frames=${2:-20}
bin=${FXCACHE:-build/server/fxcache}
[ -f "$scene" ] || { echo "sim_sweep: $scene is absent; pass a scene" >&2; exit 1; }
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

summary() { # NAME ARGS...
  local name=$1; shift
  "$bin" sim --scene "$scene" --quiet --summary "$out/$name.json" "$@" >/dev/null
}
field() { python3 -c "import json,sys; d=json.load(open('$out/$1.json')); print(eval('d' + sys.argv[1]))" "$2"; }

echo "## viewers walking together through the hall (--camera group, $scene, $frames frames, 640x360)"
echo
echo "| viewers | requested texels/frame | unique texels/frame | sharing | effect rays/frame | memory peak MiB (pools in use MiB) | frame ms | visibility | requests | queues | lookup | effects | compose |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|"
prev=""
for v in 1 2 4 8; do
  summary "walk$v" --viewers "$v" --frames "$frames" --camera group
  python3 - "$out/walk$v.json" "$v" <<'PY'
import json, sys
d = json.load(open(sys.argv[1])); f = d["frames"]; t = d["time_ms"]; m = d["memory_bytes"]
inuse = sum(e["pool_in_use"] for e in m["final"]["effects"].values())
print(f"| {sys.argv[2]} | {d['requested_texels']/f:.0f} | {d['unique_texels']/f:.0f} | {d['sharing_ratio']:.2f} | "
      f"{d['rays']['effects_total']/f:.0f} | {m['peak']['total']/2**20:.1f} ({inuse/2**20:.1f}) | {t['frame']/f:.1f} | "
      + " | ".join(f"{t[s]/f:.1f}" for s in ["visibility", "requests", "queues", "lookup", "effects", "compose"]) + " |")
PY
done
echo
echo "Marginal cost of each added viewer (difference of frame time and effect rays per frame between rows):"
python3 - "$out" <<'PY'
import json, sys
rows = [json.load(open(f"{sys.argv[1]}/walk{v}.json")) for v in (1, 2, 4, 8)]
for a, b, va, vb in zip(rows, rows[1:], (1, 2, 4), (2, 4, 8)):
    dt = (b["time_ms"]["frame"]/b["frames"] - a["time_ms"]["frame"]/a["frames"]) / (vb - va)
    dr = (b["rays"]["effects_total"]/b["frames"] - a["rays"]["effects_total"]/a["frames"]) / (vb - va)
    print(f"- {va} -> {vb} viewers: {dt:.1f} ms and {dr:.0f} effect rays per frame per added viewer")
PY
echo
echo "## steady state against --no-cache ($scene, 4 viewers, static cameras, $frames frames)"
summary static --viewers 4 --frames "$frames" --camera static --stats "$out/static.jsonl"
summary nocache --viewers 4 --frames 2 --camera static --no-cache
python3 - "$out" <<'PY'
import json, sys
lines = [json.loads(l) for l in open(f"{sys.argv[1]}/static.jsonl")]
last = lines[-1]; nc = json.load(open(f"{sys.argv[1]}/nocache.json"))
nc_rays = nc["rays"]["effects_total"] / nc["frames"]
first = lines[0]["rays"]["effects_total"]
print(f"- cache, frame 0: {first} effect rays; last frame ({last['frame']}): {last['rays']['effects_total']} effect rays")
print(f"- cache, mean over all {len(lines)} frames: {sum(l['rays']['effects_total'] for l in lines)/len(lines):.0f} effect rays per frame")
print(f"- no-cache: {nc_rays:.0f} effect rays per frame")
print(f"- steady state / no-cache: {last['rays']['effects_total']/nc_rays*100:.2f} %; mean over the run / no-cache: "
      f"{sum(l['rays']['effects_total'] for l in lines)/len(lines)/nc_rays*100:.2f} %")
print(f"- frame time: cache last frame {last['time_ms']['frame']:.1f} ms, no-cache {nc['time_ms']['frame']/nc['frames']:.1f} ms")
PY
echo
echo "## memory at level bias 0 and 2 ($scene, 4 viewers walking together, $frames frames)"
summary bias0 --viewers 4 --frames "$frames" --camera group --bias ao=0 --bias shadow=0
summary bias2 --viewers 4 --frames "$frames" --camera group --bias ao=2 --bias shadow=2
python3 - "$out" <<'PY'
import json, sys
for name in ("bias0", "bias2"):
    d = json.load(open(f"{sys.argv[1]}/{name}.json")); m = d["memory_bytes"]["final"]["effects"]
    inuse = sum(e["pool_in_use"] for k, e in m.items())
    blocks_texels = d["unique_texels"] / d["frames"]
    print(f"- {name}: pools in use at the end {inuse/2**20:.2f} MiB (shadow {m['shadow']['pool_in_use']/2**20:.2f}, ao {m['ao']['pool_in_use']/2**20:.2f}, lookup {m['triangle_lookup']['pool_in_use']/2**20:.2f}); unique texels per frame {blocks_texels:.0f}; effect rays per frame {d['rays']['effects_total']/d['frames']:.0f}")
a = json.load(open(f"{sys.argv[1]}/bias0.json"))["memory_bytes"]["final"]["effects"]
b = json.load(open(f"{sys.argv[1]}/bias2.json"))["memory_bytes"]["final"]["effects"]
ia = sum(e["pool_in_use"] for e in a.values()); ib = sum(e["pool_in_use"] for e in b.values())
print(f"- bias 0 / bias 2 memory in use: {ia/ib:.2f}x (the paper reports 1.5 to 3x)")
PY
