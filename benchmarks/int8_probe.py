#!/usr/bin/python3
"""What int8 would give geo's DepthNet on this CPU, before geo has its own int8 path: geo.nn's DepthNet
(the same network as geo's, in torch.nn) quantized by PyTorch's FX graph-mode post-training
quantization with the onednn engine (Debian's PyTorch has qnnpack and onednn, no fbgemm): weights
per channel, activations calibrated on --calibration random frames; timed against the same
module in fp32 eager at batch 1.

  PYTHONPATH=build/python python3 benchmarks/int8_probe.py --fr off --threads 2
prints one line: eager fp32 ms, int8 ms, and the mean relative difference of the finest disparity
(with untrained weights and random calibration frames: a speed probe, not an accuracy figure).

  python3 benchmarks/int8_probe.py --convs --threads 2
times single convolutions of the DepthNet's shapes at 128x416 instead: fp32, the int8 convolution
alone (quantized::conv2d_relu, prepacked per-channel weights, NHWC uint8 activations), and what
quantizing its input and dequantizing its output costs with ATen's quantize_per_tensor /
dequantize and with plain vectorised tensor arithmetic: what an int8 path that leaves activations
in float between convolutions would pay.
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


def convs(a):
    # (in, out, kernel, stride, input height, width): the encoder's first convolution, a ResNet-50
    # bottleneck's 1x1 reduction and 3x3 at 1/4 size, a 3x3 at 1/16, and a decoder 3x3 at 1/2.
    shapes = [(3, 64, 7, 2, 128, 416), (256, 64, 1, 1, 32, 104), (64, 64, 3, 1, 32, 104),
              (256, 256, 3, 1, 8, 26), (96, 32, 3, 1, 64, 208)]
    print(f"torch {torch.__version__}, {a.threads} threads, ms (median of {a.iters})")
    print("| conv | fp32 | int8 conv | ATen quantize + dequantize | vectorised quantize + dequantize |")
    print("|---|---|---|---|---|")
    with torch.inference_mode():
        for ci, co, k, st, h, w in shapes:
            x = torch.rand(1, ci, h, w).contiguous(memory_format=torch.channels_last)
            wt, b = torch.randn(co, ci, k, k) * 0.1, torch.randn(co)
            qw = torch.quantize_per_channel(wt, wt.abs().amax((1, 2, 3)) / 127, torch.zeros(co, dtype=torch.long), 0,
                                            torch.qint8)
            packed = torch.ops.quantized.conv2d_prepack(qw, b, [st, st], [k // 2, k // 2], [1, 1], 1)
            qx = torch.quantize_per_tensor(x, 1 / 255, 0, torch.quint8)
            qy = torch.ops.quantized.conv2d_relu(qx, packed, 0.05, 0)
            fp32 = median_ms(lambda: torch.relu(torch.conv2d(x, wt, b, st, k // 2)), a.iters)
            int8 = median_ms(lambda: torch.ops.quantized.conv2d_relu(qx, packed, 0.05, 0), a.iters)
            aten = median_ms(lambda: (torch.quantize_per_tensor(x, 1 / 255, 0, torch.quint8), qy.dequantize()), a.iters)
            vect = median_ms(lambda: (torch._make_per_tensor_quantized_tensor(
                x.mul(255).round_().clamp_(0, 255).to(torch.uint8), 1 / 255, 0), qy.int_repr().float().mul_(0.05)), a.iters)
            print(f"| {ci}->{co} {k}x{k}/{st} at {h}x{w} | {fp32:.2f} | {int8:.2f} | {aten:.2f} | {vect:.2f} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fr", choices=("on", "off"), default="off")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--height", type=int, default=128)
    ap.add_argument("--width", type=int, default=416)
    ap.add_argument("--iters", type=int, default=9)
    ap.add_argument("--calibration", type=int, default=4)
    ap.add_argument("--convs", action="store_true", help="time single convolutions (fp32, int8, quantize/dequantize)")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.backends.quantized.engine = "onednn"
    if a.convs:
        return convs(a)
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
