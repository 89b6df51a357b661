#!/usr/bin/python3
"""geo against PyTorch at its best, side by side: runs every variant in its own process, in rounds,
and writes the table (markdown) with the machine, versions, ceilings and commands.

Run through benchmarks/vs_pytorch.sh, which builds what is needed first. Variants:
  PyTorch 1.13 (Debian 12, this machine) and 2.6 (Debian 13 root, scripts/debian13.sh): eager fp32,
  bf16 autocast, each contiguous and channels-last, each with glibc's allocator and with jemalloc
  tuned as PyTorch's CPU performance guide advises (memory kept in the process); torch.compile
  (inductor) where the version has it, with jemalloc;
  geo_bench built on LibTorch 1.13 and on 2.6, fp32 and bf16.
Rows: DepthNet inference at batch 1, a stage-1 training step at batch 4 (128x416, FR off: GeoNet's
networks). A variant that crashes or times out is recorded as such; the table goes on.
"""
import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import time

JEMALLOC = "/usr/lib/x86_64-linux-gnu/libjemalloc.so.2"
# PyTorch's CPU performance tuning guide: jemalloc with memory kept in the process.
JEMALLOC_CONF = "oversize_threshold:1,background_thread:true,metadata_thp:auto,dirty_decay_ms:-1,muzzy_decay_ms:-1"


def pytorch_variants(platform, version):
    out = []
    compiles = (False, True) if version != "1.13" else (False,)
    for compiled in compiles:
        for precision in ("fp32", "bf16"):
            for layout in ("contiguous", "channels-last"):
                for alloc in ("glibc", "jemalloc"):
                    if compiled and alloc == "glibc":
                        continue  # compile runs once, at its best (jemalloc)
                    name = f"PyTorch {version} {'compile' if compiled else 'eager'} {precision} {layout} {alloc}"
                    args = ["--precision", precision] + (["--channels-last"] if layout == "channels-last" else [])
                    args += ["--compile"] if compiled else []
                    env = [f"LD_PRELOAD={JEMALLOC}", f"MALLOC_CONF={JEMALLOC_CONF}"] if alloc == "jemalloc" else []
                    out.append({"name": name, "platform": platform, "kind": "pytorch", "args": args, "env": env,
                                "compile": compiled})
    return out


def geo_variants(platform, version):
    return [{"name": f"geo (LibTorch {version}) {p}", "platform": platform, "kind": "geo", "precision": p}
            for p in ("fp32", "bf16")]


def command(v, row, a, tag):
    """The command line of variant v for row ('depth' | 'step'), and where its JSON lands."""
    d13 = v["platform"] == "d13"
    prefix = ["scripts/debian13.sh"] if d13 else []
    if v["kind"] == "pytorch":
        py = "python3" if d13 else "/usr/bin/python3"
        iters = a.iters if row == "depth" else a.step_iters
        cmd = prefix + ["env"] + v["env"] + [py, "benchmarks/geonet_pytorch.py", "--row", row, "--threads",
                                             str(a.threads), "--iters", str(iters)] + v["args"]
        return cmd, None
    json_name = f"geo-{v['platform']}-{v['precision']}-{row}-{tag}.json"
    json_host = os.path.join("out/debian13" if d13 else a.out, json_name)
    json_arg = f"out/{json_name}" if d13 else json_host
    bench = ("build" if d13 else a.build) + "/apps/geo_bench"
    common = [bench, "--fr", "off", "--threads", str(a.threads), "--no-comm", "--json", json_arg]
    if row == "depth":
        # fp32 and bf16 rows side by side in one process; the bf16 variant reads the bf16 row.
        cmd = common + ["--no-train", "--batch", "1", "--precision", "bf16", "--warmup", "5", "--iters", str(a.iters)]
    else:
        cmd = common + ["--no-infer", "--stage", "stage1", "--train-batch", "4", "--precision", v["precision"],
                        "--train-warmup", "2", "--train-iters", str(a.step_iters)]
    return prefix + cmd, json_host


def run(v, row, a, tag):
    cmd, json_path = command(v, row, a, tag)
    timeout = a.timeout * (3 if v.get("compile") else 1)
    t0 = time.time()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout} s"}, cmd
    took = time.time() - t0
    if p.returncode != 0:
        if p.returncode < 0:
            why = f"died with {signal.Signals(-p.returncode).name}"
        elif p.returncode > 128:
            why = f"died with {signal.Signals(p.returncode - 128).name}"
        else:
            why = f"exit {p.returncode}"
        tail = (p.stderr.strip().splitlines() or [""])[-1][:160]
        return {"error": why, "detail": tail}, cmd
    if v["kind"] == "pytorch":
        line = [l for l in p.stdout.splitlines() if l.startswith("{")][-1]
        r = json.loads(line)
        return {"ms": r["median_ms"], "torch": r["torch"], "seconds": took}, cmd
    r = json.load(open(json_path))
    want = ("DepthNet bf16" if v["precision"] == "bf16" else "DepthNet") if row == "depth" else \
        ("stage1 step bf16" if v["precision"] == "bf16" else "stage1 step")
    hit = [x for x in r["rows"] if x["what"] == want and x["section"] in ("infer", "train")][0]
    return {"ms": hit["ms"], "torch": r["libtorch"], "of_ceiling": hit.get("of_ceiling"),
            "gflops_per_s": hit.get("gflops_per_s"), "ceiling": [r.get("ceiling_gflops_fp32"),
                                                                 r.get("ceiling_gflops_bf16")],
            "seconds": took}, cmd


def cpu():
    text = open("/proc/cpuinfo").read()
    model = [l.split(": ", 1)[1] for l in text.splitlines() if l.startswith("model name")][0]
    flags = [l.split(": ", 1)[1].split() for l in text.splitlines() if l.startswith("flags")][0]
    shown = [f for f in ("avx2", "avx512f", "avx512_bf16", "amx_bf16") if f in flags]
    return f"{model}, {os.cpu_count()} logical cores, flags {' '.join(shown)}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="bench-vs-pytorch")
    ap.add_argument("--build", default="build")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--iters", type=int, default=9, help="DepthNet calls timed (median)")
    ap.add_argument("--step-iters", type=int, default=3, help="training steps timed (median)")
    ap.add_argument("--timeout", type=int, default=600, help="seconds per variant (3x for torch.compile)")
    ap.add_argument("--platforms", default="d12,d13")
    ap.add_argument("--rows", default="depth,step")
    ap.add_argument("--only", default="", help="run only variants whose name contains this")
    ap.add_argument("--merge", action="store_true",
                    help="the table also holds the variants not run now, from earlier runs in OUT/runs.jsonl")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    platforms = a.platforms.split(",")
    variants = []
    for platform, version in (("d12", "1.13"), ("d13", "2.6")):
        if platform in platforms:
            variants += pytorch_variants(platform, version) + geo_variants(platform, version)
    all_variants = list(variants)
    variants = [v for v in variants if a.only in v["name"]]
    torch_ceilings = []
    for platform, version in (("d12", "1.13"), ("d13", "2.6")):
        if platform not in platforms:
            continue
        cmd = (["scripts/debian13.sh", "python3"] if platform == "d13" else ["/usr/bin/python3"]) + \
            ["benchmarks/geonet_pytorch.py", "--row", "ceiling", "--threads", str(a.threads)]
        p = subprocess.run(cmd, capture_output=True, text=True)
        line = [l for l in p.stdout.splitlines() if l.startswith("{")]
        if line:
            c = json.loads(line[-1])
            torch_ceilings.append(f"- PyTorch {c['torch']}'s `torch.mm` (the same product): "
                                  f"{c['ceiling_gflops_fp32']:.0f} GFLOP/s fp32, {c['ceiling_gflops_bf16']:.0f} GFLOP/s bf16.")
    results, commands, earlier = {}, {}, {}
    log = open(os.path.join(a.out, "runs.jsonl"), "a")
    for r in range(1, a.rounds + 1):
        for row in a.rows.split(","):
            # Alternate the platforms within a round, so that a slow spell hits both alike.
            order = sorted(variants, key=lambda v: (v["kind"] == "geo", v["name"].split()[2:], v["platform"]))
            for v in order:
                res, cmd = run(v, row, a, f"r{r}")
                key = (v["name"], row)
                results.setdefault(key, []).append(res)
                commands[key] = " ".join(cmd)
                shown = f"{res['ms']:.1f} ms" if "ms" in res else res["error"]
                print(f"round {r} {row:<5} {v['name']:<55} {shown}", file=sys.stderr, flush=True)
                log.write(json.dumps({"round": r, "row": row, "variant": v["name"], **res}) + "\n")
                log.flush()

    if a.merge and os.path.exists(os.path.join(a.out, "runs.jsonl")):
        by_name = {v["name"]: v for v in all_variants}
        for line in open(os.path.join(a.out, "runs.jsonl")):
            x = json.loads(line)
            key = (x["variant"], x["row"])
            if key in results or x["variant"] not in by_name:
                continue
            earlier.setdefault(key, []).append({k: v for k, v in x.items() if k not in ("round", "row", "variant")})
        for key, res in earlier.items():
            results[key] = res
            commands[key] = " ".join(command(by_name[key[0]], key[1], a, "r1")[0])
    lines = [f"Measured {time.strftime('%Y-%m-%d')} on {cpu()}; {a.threads} threads; 128x416, FR off "
             f"(GeoNet's networks); {a.rounds} round(s), each variant in its own process, median of {a.iters} "
             f"DepthNet calls after 5 warm-ups / {a.step_iters} training steps after 2.",
             f"Command: `benchmarks/vs_pytorch.sh` (rounds {a.rounds}).", ""]
    for row, title in (("depth", "DepthNet inference, batch 1"), ("step", "Stage-1 training step, batch 4")):
        if row not in a.rows.split(","):
            continue
        rows = [(name, res) for (name, rw), res in results.items() if rw == row]
        def best(res):
            ms = [x["ms"] for x in res if "ms" in x]
            return min(ms) if ms else None
        torch_best = [(best(res), name) for name, res in rows if name.startswith("PyTorch") and best(res)]
        ref_ms, ref_name = min(torch_best) if torch_best else (None, "")
        lines += [f"**{title}** (reference: the fastest PyTorch variant, {ref_name}, {ref_ms:.1f} ms)"
                  if ref_ms else f"**{title}**", "",
                  "| variant | " + " | ".join(f"round {i} ms" for i in range(1, a.rounds + 1)) +
                  " | best / reference | share of the ceiling |",
                  "|---|" + "---|" * a.rounds + "---|---|"]
        for name, res in sorted(rows, key=lambda x: (best(x[1]) is None, best(x[1]) or 0)):
            cells = [f"{x['ms']:.1f}" if "ms" in x else x["error"] for x in res]
            b = best(res)
            shares = [x.get("of_ceiling") for x in res if x.get("of_ceiling")]
            lines.append(f"| {name} | " + " | ".join(cells) +
                         f" | {b / ref_ms:.2f} |" if b and ref_ms else f"| {name} | " + " | ".join(cells) + " | - |")
            lines[-1] += f" {100 * max(shares):.0f}% |" if shares else " - |"
        lines.append("")
    by_version = {}
    for res in results.values():
        for x in res:
            if "ceiling" in x:
                by_version.setdefault(x["torch"], []).append(x["ceiling"])
    for version, cs in sorted(by_version.items()):
        fp32, bf16 = [c[0] for c in cs], [c[1] for c in cs]
        lines.append(f"- The ceiling geo_bench measured with LibTorch {version} (a 2048x2048 matrix product, the best of 7, "
                     f"in each of its {len(cs)} processes): {min(fp32):.0f}-{max(fp32):.0f} GFLOP/s fp32, "
                     f"{min(bf16):.0f}-{max(bf16):.0f} GFLOP/s bf16. A row's share: its FLOPs (a training step: 3x its "
                     f"forward's) per second over its own process's ceiling.")
    lines += torch_ceilings
    errors = [(k, x) for k, res in results.items() for x in res if "error" in x]
    for (name, row), x in errors:
        lines.append(f"- {name}, {row}: {x['error']}" + (f" ({x['detail']})" if x.get("detail") else ""))
    lines += ["", "Commands (one per variant and row):", ""]
    lines += [f"- `{c}`" for c in sorted(set(commands.values()))]
    table = "\n".join(lines) + "\n"
    open(os.path.join(a.out, "table.md"), "w").write(table)
    print(table)


if __name__ == "__main__":
    main()
