#!/usr/bin/python3
"""GeoNet's ResNet-50 DepthNet in eager PyTorch: the reference geo's CPU inference is compared with.

This is the network the PyTorch GeoNet ports run (GeoNet's disp_net_res50: ResNet-50 with the
stride in the last block of each stage and a projection shortcut in every block, conv + BatchNorm
+ ReLU everywhere, a decoder of nearest-upsample + 3x3 conv "upconvs" with skip connections and
four disparity heads 10 * sigmoid + 0.01), written here as a PyTorch user would write it: nn.Conv2d
/ nn.BatchNorm2d modules, eval mode, no BatchNorm folding. Same parameter count as geo's DepthNet
with FR off (printed, and checked by scripts/bench_vs_pytorch.sh).

  python3 scripts/pytorch_reference.py --threads 2 --iters 9 [--height 128 --width 416 --batch 1]
prints one JSON line: {"params": N, "median_ms": x, "times_ms": [...], "torch": version, ...}.
"""
import argparse
import json
import statistics
import time

import torch
import torch.nn as nn
import torch.nn.functional as F


def conv_bn(cin, cout, k, stride=1, relu=True):
    layers = [nn.Conv2d(cin, cout, k, stride, k // 2, bias=False), nn.BatchNorm2d(cout, eps=1e-3)]
    if relu:
        layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


class Bottleneck(nn.Module):
    def __init__(self, cin, n, stride):
        super().__init__()
        self.body = nn.Sequential(conv_bn(cin, n, 1), conv_bn(n, n, 3, stride), conv_bn(n, 4 * n, 1, relu=False))
        self.shortcut = conv_bn(cin, 4 * n, 1, stride, relu=False)

    def forward(self, x):
        return F.relu(self.body(x) + self.shortcut(x))


class Encoder(nn.Module):
    def __init__(self):
        super().__init__()
        self.conv1 = conv_bn(3, 64, 7, 2)
        stages, cin = [], 64
        for width, blocks in zip((64, 128, 256, 512), (3, 4, 6, 3)):
            layers = []
            for b in range(blocks):
                layers.append(Bottleneck(cin, width, 2 if b == blocks - 1 else 1))
                cin = 4 * width
            stages.append(nn.Sequential(*layers))
        self.stages = nn.ModuleList(stages)

    def forward(self, x):
        feats = [self.conv1(x)]
        feats.append(F.max_pool2d(feats[-1], 3, 2, 1))
        for s in self.stages:
            feats.append(s(feats[-1]))
        return feats  # H/2, H/4, H/8, H/16, H/32, H/64


def resize_like(x, ref):
    return x[:, :, : ref.shape[2], : ref.shape[3]]


class DepthNet(nn.Module):
    WIDTHS = (512, 256, 128, 64, 32, 16)
    SKIPS = (1024, 512, 256, 64, 64)  # stage3, stage2, stage1, pool1, conv1 channels

    def __init__(self):
        super().__init__()
        self.encoder = Encoder()
        self.upconv, self.iconv, self.pred = nn.ModuleList(), nn.ModuleList(), nn.ModuleList()
        cin = 2048
        for k, width in enumerate(self.WIDTHS):
            self.upconv.append(conv_bn(cin, width, 3))
            cat = width + (self.SKIPS[k] if k < 5 else 0) + (1 if k >= 3 else 0)
            self.iconv.append(conv_bn(cat, width, 3))
            if k >= 2:
                self.pred.append(nn.Conv2d(width, 1, 3, 1, 1))
            cin = width

    def forward(self, image):
        x = image * 2 - 1
        feats = self.encoder(x)
        y, disps = feats[5], []
        for k in range(6):
            ref = feats[4 - k] if k < 5 else x
            parts = [resize_like(self.upconv[k](F.interpolate(y, scale_factor=2, mode="nearest")), ref)]
            if k < 5:
                parts.append(feats[4 - k])
            if k >= 3:
                parts.append(resize_like(F.interpolate(disps[-1], scale_factor=2, mode="nearest"), ref))
            y = self.iconv[k](torch.cat(parts, 1))
            if k >= 2:
                disps.append(10 * torch.sigmoid(self.pred[k - 2](y)) + 0.01)
        return disps[::-1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--height", type=int, default=128)
    ap.add_argument("--width", type=int, default=416)
    ap.add_argument("--batch", type=int, default=1)
    ap.add_argument("--threads", type=int, default=0, help="intra-op threads (0: PyTorch's default)")
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--iters", type=int, default=9)
    ap.add_argument("--params-only", action="store_true")
    a = ap.parse_args()
    if a.threads > 0:
        torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    net = DepthNet().eval()
    params = sum(p.numel() for p in net.parameters())
    out = {"what": "PyTorch GeoNet ResNet-50 DepthNet (eager, fp32, eval)", "params": params,
           "torch": torch.__version__, "threads": torch.get_num_threads(),
           "batch": a.batch, "height": a.height, "width": a.width}
    if not a.params_only:
        img = torch.rand(a.batch, 3, a.height, a.width)
        times = []
        with torch.inference_mode():
            for i in range(a.warmup + a.iters):
                t0 = time.perf_counter()
                net(img)
                if i >= a.warmup:
                    times.append(1e3 * (time.perf_counter() - t0))
        out["median_ms"] = statistics.median(times)
        out["times_ms"] = [round(t, 2) for t in times]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
