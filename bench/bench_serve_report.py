# The tables of bench/bench_serve.sh from its folder of raw files (can be rerun on a finished folder):
#   python3 bench/bench_serve_report.py DIR COUNTS REPEATS FRAMES
import json, statistics, sys
out, counts, repeats, frames = sys.argv[1], sys.argv[2].split(), int(sys.argv[3]), int(sys.argv[4])
warm = 10
def lines(path):
    return [json.loads(l) for l in open(path)]
def stage_times(rows):
    keys = [k for k in rows[0]["time_ms"] if k != "frame"]
    return {k: statistics.median(r["time_ms"][k] for r in rows) for k in keys}
def cpu(path):
    try:
        e, u, s_ = open(path).read().split()[:3]
        return float(u) + float(s_)
    except (OSError, ValueError):
        return float("nan")
print("\n| viewers | serve ms/frame | sim ms/frame | serve/sim frame time (per repeat) | serve/sim CPU s (per repeat) | fps per viewer | latency median | latency p95 | bytes/frame (zstd) |")
print("|---|---|---|---|---|---|---|---|---|")
for n in counts:
    ratios, serve_ms, sim_ms, fpss, lat50, lat95, bpf, cpus = [], [], [], [], [], [], [], []
    for r in range(repeats):
        tag = f"{out}/n{n}.r{r}"
        se, si = lines(tag + ".serve.jsonl"), lines(tag + ".sim.jsonl")
        # Frames with viewers present in both, after the warm-up: the same frames, same cameras.
        m = min(len(se), len(si))
        se_ms = [x["time_ms"]["frame"] for x in se[warm:m] if x["viewers"]]
        si_ms = [x["time_ms"]["frame"] for x in si[warm:m] if x["viewers"]]
        a, b = statistics.median(se_ms), statistics.median(si_ms)
        serve_ms.append(a); sim_ms.append(b); ratios.append(a / b)
        cpus.append(cpu(tag + ".serve.time") / cpu(tag + ".sim.time"))
        c = json.load(open(tag + ".client.json"))
        for v in c["viewers"]:
            fpss.append(v["fps"]); lat50.append(v["latency_ms"]["median"]); lat95.append(v["latency_ms"]["p95"])
            bpf.append(v["bytes_per_frame"])
    print(f"| {n} | {statistics.median(serve_ms):.1f} | {statistics.median(sim_ms):.1f} | "
          f"{statistics.median(ratios):.3f} ({', '.join(f'{x:.3f}' for x in ratios)}) | "
          f"{statistics.median(cpus):.3f} ({', '.join(f'{x:.3f}' for x in cpus)}) | {statistics.median(fpss):.1f} | "
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
          f"{statistics.median(x['fps'] for x in v):.1f} | {statistics.median(x['latency_ms']['median'] for x in v):.0f} ms |")
