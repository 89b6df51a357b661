#!/usr/bin/python3
"""What int8 would give geo's DepthNet on this CPU, before geo has its own int8 path: geo.nn's DepthNet
(the same network as geo's, in torch.nn) quantized by PyTorch's FX graph-mode post-training
quantization with the onednn engine (Debian's PyTorch has qnnpack and onednn, no fbgemm): weights
per channel, activations calibrated on --calibration random frames; timed against the same
module in fp32 eager at batch 1.

  PYTHONPATH=build/python python3 scripts/int8_probe.py --fr off --threads 2
prints one line: eager fp32 ms, int8 ms, and the mean relative difference of the finest disparity
(with untrained weights and random calibration frames: a speed probe, not an accuracy figure).
"""
import argparse
import time

import torch
from torch.ao.quantization import get_default_qconfig_mapping
from torch.ao.quantization.quantize_fx import convert_fx, prepare_fx

import geo.nn


def median_ms(f, n):
    for _ in range(3):
        f()
    times = []
    for _ in range(n):
        start = time.perf_counter()
        f()
        times.append((time.perf_counter() - start) * 1000)
    return sorted(times)[n // 2]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fr", choices=("on", "off"), default="off")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--height", type=int, default=128)
    ap.add_argument("--width", type=int, default=416)
    ap.add_argument("--iters", type=int, default=9)
    ap.add_argument("--calibration", type=int, default=4)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.backends.quantized.engine = "onednn"
    torch.manual_seed(0)
    model = {"encoder_depth": 50, "use_fr": a.fr == "on", "fr_encoder": True, "fr_decoder": True, "fr_ratio": 16,
             "fr_spatial_bn": False, "upsample": "nearest", "bn_eps": 1e-3}
    net = geo.nn.DepthNet(model).eval()
    x = torch.rand(1, 3, a.height, a.width)
    prepared = prepare_fx(net, get_default_qconfig_mapping("onednn"), (x,))
    with torch.no_grad():
        for _ in range(a.calibration):
            prepared(torch.rand(1, 3, a.height, a.width))
    int8 = convert_fx(prepared)
    with torch.inference_mode():
        fp32_ms = median_ms(lambda: net(x), a.iters)
        int8_ms = median_ms(lambda: int8(x), a.iters)
        ref, out = net(x)[0], int8(x)[0]
    diff = ((out - ref).abs() / ref).mean().item()
    print(f"DepthNet FR {a.fr}, {a.height}x{a.width}, batch 1, {a.threads} threads, torch {torch.__version__}: "
          f"fp32 eager {fp32_ms:.1f} ms, int8 (FX, onednn) {int8_ms:.1f} ms, mean relative disparity difference {diff:.4f}")


if __name__ == "__main__":
    main()
