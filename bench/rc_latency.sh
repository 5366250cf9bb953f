#!/bin/sh
# The render cache's latency benchmark (issue 11; figures in docs/BENCHMARKS.md, "The viewer client's render
# cache"): a rapid-turn camera trace on Sponza, shown by fxcache-viewer with 50, 100 and 200 ms of simulated
# latency each way (--latency: cameras held that long before they are sent, frames and answers after they
# arrive), three ways: the last frame received, reprojection through the render cache without prediction, and
# with prediction. Every display frame (30 a second) is compared with the true view: the server's own render of
# that display frame's camera (fxcache sim --trace on the display cameras the viewer recorded, same scene, same
# settings, same 30 fps clock), as RMSE of the 8-bit sRGB values, leaving out the first WARMUP seconds.
#
#   bench/rc_latency.sh BUILD_DIR OUT_DIR [extra fxcache-viewer options, e.g. --sample-budget 0]
#
# Each run has a server of its own (fresh caches), started on Sponza and stopped after the viewer ends.
# The session runs SCALE times slower than the wall clock (fxcache-viewer --time-scale, the server at 30 / SCALE
# frames a second): it stands for a server rendering 30 frames a second on a machine SCALE times faster, so the
# figures do not depend on how loaded this one is (at SCALE 1 a loaded machine adds its own seconds of latency).
# Environment: SCENE (default ../shared/scenes/sponza/sponza.3ds from the repository), RES (320x180),
# LATENCIES ("50 100 200"), WARMUP (2 seconds), SCALE (4), EFFECTS (shadow: the sun's shadows; both the server
# and the true view use it).
set -eu
build=$1
out=$2
shift 2
here=$(cd "$(dirname "$0")/.." && pwd)
scene=${SCENE:-$here/../shared/scenes/sponza/sponza.3ds}
res=${RES:-320x180}
latencies=${LATENCIES:-50 100 200}
warmup=${WARMUP:-2}
scale=${SCALE:-4}
effects=${EFFECTS:-shadow}
server_fps=$(awk -v s="$scale" 'BEGIN { printf "%.6g", 30 / s }')
fxcache=$build/server/fxcache
viewer=$build/viewer_client/fxcache-viewer
error=$build/bench/bench_display_error
mkdir -p "$out"

# The trace: walking down Sponza's courtyard (x from -9 to 9 m, 1.5 m up) for 9 s while the view swings
# 60 degrees either side of +x and back every 3 s (peak turn rate 126 degrees a second), a line every 1/60 s.
awk 'BEGIN {
    print "fxcache-trace 1"
    print "# bench/rc_latency.sh: a rapid turn while walking down the courtyard of Sponza"
    pi = 3.14159265358979
    for (i = 0; i <= 540; i++) {
        t = i / 60; yaw = (60 * pi / 180) * sin(2 * pi * t / 3)
        printf "%.6f %.6f 1.5 0 %.9f -0.05 %.9f 60\n", t, -9 + 2 * t, cos(yaw), sin(yaw)
    }
}' > "$out/turn.trace"

run() { # run NAME OPTIONS...: a fresh server, the viewer on the trace, the server stopped
    name=$1
    shift
    rm -rf "$out/$name"
    "$fxcache" serve --scene "$scene" --effects "$effects" --port 0 --fps "$server_fps" --quiet > "$out/$name.serve" 2>&1 &
    server=$!
    port=
    for _ in $(seq 1 600); do
        port=$(sed -n 's/.*listening on ws:\/\/127.0.0.1:\([0-9]*\).*/\1/p' "$out/$name.serve")
        [ -n "$port" ] && break
        sleep 0.1
    done
    [ -n "$port" ] || { echo "rc_latency.sh: the server did not start (see $out/$name.serve)" >&2; exit 1; }
    "$viewer" --connect "ws://127.0.0.1:$port" --trace "$out/turn.trace" --res "$res" --display-fps 30 \
        --time-scale "$scale" --display-out "$out/$name" --stats "$out/$name.json" --timeout 120 --quiet "$@"
    kill "$server"
    wait "$server" || true
}

for latency in $latencies; do
    run "last_$latency" --latency "$latency"
    run "reproject_$latency" --latency "$latency" --reproject --no-prediction "$@"
    run "predict_$latency" --latency "$latency" --reproject --strategy predictive "$@"
done

# The true view: display frame k's camera is the trace at k / 30 s in every run, so the display cameras of all
# runs are merged into one trace (by time, each once) and rendered once. A display clock that falls behind skips
# frames and writes no line for them, so no single run's trace need hold every frame another run showed: sim
# would render the line before for a missing one (display frame 92 of a 100 ms run was compared with frame 91's
# camera, 4 degrees of turn away: RMSE 17.5 against 5 for its neighbours).
truth_trace="$out/display_cameras.trace"
first=$(ls "$out"/*/display_viewer_00.trace | head -n 1)
{
    grep -v '^[0-9.-]' "$first"
    cat "$out"/*/display_viewer_00.trace | grep '^[0-9]' | sort -g -k1,1 | awk '!seen[$1]++'
} > "$truth_trace"
rm -rf "$out/truth"
"$fxcache" sim --scene "$scene" --effects "$effects" --trace "$truth_trace" --fps 30 --out "$out/truth" --save-every 1 --quiet

echo "# display frames from ${warmup} s on; RMSE of 8-bit sRGB against the server's render of the same camera"
for latency in $latencies; do
    for mode in last reproject predict; do
        "$error" "$out/${mode}_$latency" "$out/truth" --from "$warmup" --label "$mode $latency ms"
    done
done
