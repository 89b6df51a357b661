#!/usr/bin/python3
"""geo against ONNX Runtime's CPU engine, side by side in one run (benchmarks/vs_onnxruntime.sh
sets it up). DepthNet inference at batch 1 and --height x --width on --threads threads:

  geo fp32 / bf16 / int8 geo_bench's "infer DepthNet" rows (BatchNorm folded; int8 calibrated on
                         random frames), FR off and on
  ORT geo's DepthNet     geo.nn.DepthNet (the same network in torch.nn) exported with torch.onnx.export
  ORT GeoNet's DepthNet  benchmarks/geonet_pytorch.py's, exported the same way (the reference a
                         deployment user would start from)
  PyTorch fp32 / bf16    GeoNet's DepthNet in eager PyTorch (benchmarks/geonet_pytorch.py; Debian's
                         python3-torch, the LibTorch geo links), fp32 and bf16 autocast
  ORT int8               each of those quantized statically to ONNX's QDQ form (benchmarks/ort_qdq.py:
                         MinMax calibration on 8 inputs through ONNX Runtime, uint8 activations, int8
                         weights per channel), which ONNX Runtime runs with its int8 kernels

Variants are interleaved within each round (a slow spell hits all alike); the table gives each
one's median over rounds of its per-run medians, and geo / ORT at equal precision and FR.
"""
import argparse
import json
import os
import pathlib
import platform
import statistics
import subprocess
import sys


def cpu():
    model, flags = platform.processor(), ""
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name") and model in ("", "x86_64"):
                model = line.split(":", 1)[1].strip()
            if line.startswith("flags") and not flags:
                have = set(line.split(":", 1)[1].split())
                flags = " ".join(f for f in ("avx2", "avx512f", "avx512_vnni", "avx512_bf16", "amx_bf16", "amx_int8") if f in have)
    except OSError:
        pass
    return model, flags


def geo_ms(a, fr):
    """geo_bench's DepthNet rows, fp32, bf16 and int8 from one process: {"geo fp32": ms, ...}."""
    out = a.out / f"geo-{fr}.json"
    cmd = [str(a.build / "apps" / "geo_bench"), "--set", f"data.height={a.height}", f"data.width={a.width}", "--batch", "1",
           "--fr", fr, "--no-train", "--no-comm", "--no-ceiling", "--threads", str(a.threads), "--iters", str(a.iters),
           "--warmup", "3", "--precision", "bf16" if a.bf16 else "fp32", "--int8", "--json", str(out)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rows = {r["what"]: r["ms"] for r in json.load(open(out))["rows"] if r["section"] == "infer"}
    ms = {"geo fp32": rows["DepthNet"], "geo int8": rows["DepthNet int8"]}
    if a.bf16:
        ms["geo bf16"] = rows["DepthNet bf16"]
    return ms


def pytorch_ms(a, precision):
    """GeoNet's DepthNet in eager PyTorch (benchmarks/geonet_pytorch.py), batch 1."""
    cmd = [sys.executable, str(a.repo / "benchmarks" / "geonet_pytorch.py"), "--row", "depth", "--height", str(a.height),
           "--width", str(a.width), "--threads", str(a.threads), "--iters", str(a.iters), "--warmup", "3",
           "--precision", precision]
    r = subprocess.run(cmd, check=True, capture_output=True, text=True)
    a.torch_version = json.loads(r.stdout.strip().splitlines()[-1]).get("torch", "?")
    return json.loads(r.stdout.strip().splitlines()[-1])["median_ms"]


def ort(a, *args):
    """benchmarks/ort_bench.mjs with args; its JSON line, if it printed one."""
    cmd = ["node", str(a.repo / "benchmarks" / "ort_bench.mjs"), *map(str, args)]
    r = subprocess.run(cmd, check=True, capture_output=True, text=True, env={**os.environ, "GEO_ORT_DIR": str(a.ort)})
    lines = r.stdout.strip().splitlines()
    return json.loads(lines[-1]) if lines else None


def ort_ms(a, model, reference=None):
    line = ort(a, model, "--threads", a.threads, "--iters", a.iters, "--warmup", 3,
               *(["--reference", reference] if reference else []))
    a.ort_version = line["onnxruntime"]
    if reference:
        a.int8_error[pathlib.Path(model).name] = line["relative_error"]
    return line["median_ms"]


def ort_int8(a, model):
    """model quantized for ONNX Runtime (benchmarks/ort_qdq.py): optimised by ONNX Runtime (basic), every
    activation's range over 8 calibration inputs, then the QDQ model."""
    stem = model.with_suffix("")
    optimized, augmented = f"{stem}-opt.onnx", f"{stem}-augmented.onnx"
    ranges, out = f"{stem}-ranges.json", a.out / f"{stem.name}-int8.onnx"
    qdq = [sys.executable, str(a.repo / "benchmarks" / "ort_qdq.py")]
    ort(a, model, "--optimized", optimized)
    subprocess.run(qdq + ["augment", optimized, augmented], check=True)
    ort(a, augmented, "--ranges", ranges, "--calibration", 8)
    subprocess.run(qdq + ["quantize", optimized, ranges, str(out)], check=True, stdout=subprocess.DEVNULL)
    for f in (optimized, augmented):
        os.remove(f)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", default="build")
    ap.add_argument("--ort", required=True, help="folder whose node_modules holds onnxruntime-node")
    ap.add_argument("--out", default="bench-vs-pytorch")
    ap.add_argument("--height", type=int, default=128)
    ap.add_argument("--width", type=int, default=416)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--iters", type=int, default=9)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    # bf16 rows only where the CPU computes in bf16 (AVX512-BF16 or AMX): elsewhere LibTorch emulates
    # it in fp32 at several times fp32's time, which measures nothing a user would run.
    model, flags = cpu()
    a.bf16 = any(f in flags.split() for f in ("avx512_bf16", "amx_bf16"))
    if not a.bf16:
        print("vs_onnxruntime: this CPU has neither AVX512-BF16 nor AMX: the bf16 rows are left out", flush=True)
    a.repo = pathlib.Path(__file__).resolve().parents[1]
    a.build, a.ort, a.out = pathlib.Path(a.build).resolve(), pathlib.Path(a.ort).resolve(), pathlib.Path(a.out).resolve()
    a.out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(a.build / "python")}
    models = {}
    for fr in ("off", "on"):
        models[("geo", fr)] = a.out / f"geo-depth-fr-{fr}.onnx"
        code = ("import sys, torch, geo.nn\n"
                f"m = {{'encoder_depth': 50, 'use_fr': {fr == 'on'}, 'fr_encoder': True, 'fr_decoder': True, 'fr_ratio': 16,"
                " 'fr_spatial_bn': False, 'upsample': 'nearest', 'bn_eps': 1e-3}\n"
                f"torch.onnx.export(geo.nn.DepthNet(m).eval(), torch.rand(1, 3, {a.height}, {a.width}), sys.argv[1],"
                " input_names=['image'], opset_version=13)\n")
        subprocess.run([sys.executable, "-c", code, str(models[("geo", fr)])], check=True, env=env,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    models[("geonet", "off")] = a.out / "geonet-depth.onnx"
    subprocess.run([sys.executable, str(a.repo / "benchmarks" / "geonet_pytorch.py"), "--height", str(a.height), "--width",
                    str(a.width), "--export-onnx", str(models[("geonet", "off")])], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # Each entry: FR, what it runs -> {variant name: ms}.
    int8 = {k: ort_int8(a, m) for k, m in models.items()}
    a.int8_error = {}
    runs = [("off", lambda: geo_ms(a, "off")),
            ("off", lambda: {"ORT fp32, geo's DepthNet": ort_ms(a, models[("geo", "off")])}),
            ("off", lambda: {"ORT int8, geo's DepthNet": ort_ms(a, int8[("geo", "off")], models[("geo", "off")])}),
            ("off", lambda: {"ORT fp32, GeoNet's DepthNet": ort_ms(a, models[("geonet", "off")])}),
            ("off", lambda: {"PyTorch fp32 eager, GeoNet's DepthNet": pytorch_ms(a, "fp32")}),
            ("off", lambda: {"PyTorch bf16 eager, GeoNet's DepthNet": pytorch_ms(a, "bf16")} if a.bf16 else {}),
            ("off", lambda: {"ORT int8, GeoNet's DepthNet": ort_ms(a, int8[("geonet", "off")], models[("geonet", "off")])}),
            ("on", lambda: geo_ms(a, "on")),
            ("on", lambda: {"ORT fp32, geo's DepthNet": ort_ms(a, models[("geo", "on")])}),
            ("on", lambda: {"ORT int8, geo's DepthNet": ort_ms(a, int8[("geo", "on")], models[("geo", "on")])})]
    times = {}
    for r in range(a.rounds):
        for fr, run in runs:
            for name, ms in run().items():
                times.setdefault((name, fr), []).append(ms)
                print(f"round {r + 1}/{a.rounds}: {name}, FR {fr}: {ms:.1f} ms", flush=True)
    variants = list(times)
    med = {k: statistics.median(v) for k, v in times.items()}
    lines = [f"DepthNet inference, batch 1, {a.height}x{a.width}, {a.threads} threads, median of {a.rounds} rounds "
             f"(each the median of {a.iters} runs); CPU {model} ({flags}); ONNX Runtime {a.ort_version} (onnxruntime-node); "
             f"PyTorch {a.torch_version} (eager); "
             f"command: benchmarks/vs_onnxruntime.sh --rounds {a.rounds} --iters {a.iters}", "",
             "| variant | FR | ms | per round | geo fp32 / this | geo / this at equal precision |", "|---|---|---|---|---|---|"]
    for name, fr in variants:
        ratio = med[("geo fp32", fr)] / med[(name, fr)]
        precision = next(p for p in ("int8", "bf16", "fp32") if p in name)
        equal = f"{med[(f'geo {precision}', fr)] / med[(name, fr)]:.2f}" if not name.startswith("geo") else "-"
        lines.append(f"| {name} | {fr} | {med[(name, fr)]:.1f} | {' '.join(f'{t:.0f}' for t in times[(name, fr)])} "
                     f"| {ratio:.2f} | {equal} |")
    lines += ["", "ONNX Runtime's int8 models against their float selves (mean |difference| / mean |float| of the "
              "full-resolution disparity, one input): " +
              ", ".join(f"{k} {v * 100:.2f}%" for k, v in sorted(a.int8_error.items()))]
    table = "\n".join(lines) + "\n"
    (a.out / "onnxruntime.md").write_text(table)
    print(table)


if __name__ == "__main__":
    main()
