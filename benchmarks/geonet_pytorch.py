#!/usr/bin/python3
"""GeoNet's networks and stage-1 training step in PyTorch: the reference geo's CPU speed is compared with.

This is the network the PyTorch GeoNet ports run (GeoNet's disp_net_res50: ResNet-50 with the
stride in the last block of each stage and a projection shortcut in every block, conv + BatchNorm
+ ReLU everywhere, a decoder of nearest-upsample + 3x3 conv "upconvs" with skip connections and
four disparity heads 10 * sigmoid + 0.01), written here as a PyTorch user would write it: nn.Conv2d
/ nn.BatchNorm2d modules, eval mode, no BatchNorm folding. Same parameter count as geo's DepthNet
with FR off (printed, and checked by benchmarks/vs_pytorch.sh).

Also GeoNet's PoseNet (7 strided conv + BatchNorm + ReLU layers and a 1x1 pose head) and its
stage-1 training step ("train_rigid"): the DepthNet on the target and source frames, the PoseNet on
the snippet, rigid flow from depth and pose in both directions at 4 scales, bilinear warping,
SSIM + L1 reconstruction (alpha 0.85), edge-aware disparity smoothness, backward, Adam.

  python3 benchmarks/geonet_pytorch.py --row depth --threads 2 --iters 9    DepthNet inference, batch 1
  python3 benchmarks/geonet_pytorch.py --row step --batch 4 --iters 3       a stage-1 training step
  python3 benchmarks/geonet_pytorch.py --row ceiling                        a large fp32/bf16 matrix product
  python3 benchmarks/geonet_pytorch.py --row step --device cuda             the same step on a GPU (eager PyTorch)
  python3 benchmarks/geonet_pytorch.py --export-onnx depth.onnx                   the DepthNet as ONNX (ONNX Runtime's input)
  options: --precision fp32|bf16 (bf16: the networks under torch.autocast, the losses in fp32),
           --channels-last, --compile (torch.compile, PyTorch >= 2.0)
prints one JSON line: {"row": ..., "median_ms": x, "times_ms": [...], "torch": version, ...}.
"""
import argparse
import contextlib
import json
import statistics
import sys
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



class PoseNet(nn.Module):
    """GeoNet's pose_net: conv 16 7x7, 32 5x5, 64..256 3x3, all stride 2 with BatchNorm + ReLU; a 1x1
    conv to 6 values per source, averaged over the image, x 0.01."""

    def __init__(self, num_source=2):
        super().__init__()
        layers, cin = [], 3 * (num_source + 1)
        for cout, k in ((16, 7), (32, 5), (64, 3), (128, 3), (256, 3), (256, 3), (256, 3)):
            layers.append(conv_bn(cin, cout, k, 2))
            cin = cout
        self.body = nn.Sequential(*layers)
        self.head = nn.Conv2d(256, 6 * num_source, 1)
        self.num_source = num_source

    def forward(self, tgt, srcs):
        x = self.head(self.body(torch.cat([tgt] + srcs, 1) * 2 - 1))
        return 0.01 * x.mean((2, 3)).view(-1, self.num_source, 6)


def euler_to_matrix(pose):
    """[B,6] (tx, ty, tz, rx, ry, rz) -> [B,3,4], rotation R = Rx Ry Rz as GeoNet's pose_vec2mat."""
    t, (rx, ry, rz) = pose[:, :3], pose[:, 3:].unbind(1)
    one, zero = torch.ones_like(rx), torch.zeros_like(rx)
    cz, sz, cy, sy, cx, sx = rz.cos(), rz.sin(), ry.cos(), ry.sin(), rx.cos(), rx.sin()
    Rz = torch.stack([cz, -sz, zero, sz, cz, zero, zero, zero, one], 1).view(-1, 3, 3)
    Ry = torch.stack([cy, zero, sy, zero, one, zero, -sy, zero, cy], 1).view(-1, 3, 3)
    Rx = torch.stack([one, zero, zero, zero, cx, -sx, zero, sx, cx], 1).view(-1, 3, 3)
    return torch.cat([Rx @ Ry @ Rz, t.unsqueeze(2)], 2)


def rigid_flow(depth, pose, K, inverse):
    """Flow [B,2,H,W] that moves each pixel of the frame with `depth` [B,1,H,W] by the camera motion."""
    B, _, H, W = depth.shape
    ys, xs = torch.meshgrid(torch.arange(H, dtype=depth.dtype), torch.arange(W, dtype=depth.dtype), indexing="ij")
    pix = torch.stack([xs, ys, torch.ones_like(xs)]).view(1, 3, -1).expand(B, 3, H * W)
    cam = (torch.linalg.inv(K) @ pix) * depth.view(B, 1, -1)
    T = euler_to_matrix(pose)
    if inverse:
        R_inv = T[:, :, :3].transpose(1, 2)
        T = torch.cat([R_inv, -R_inv @ T[:, :, 3:]], 2)
    p = K @ (T[:, :, :3] @ cam + T[:, :, 3:])
    uv = p[:, :2] / p[:, 2:].clamp(min=1e-3)
    return (uv - pix[:, :2]).view(B, 2, H, W)


def flow_warp(img, flow):
    B, _, H, W = img.shape
    ys, xs = torch.meshgrid(torch.arange(H, dtype=img.dtype), torch.arange(W, dtype=img.dtype), indexing="ij")
    x = (xs + flow[:, 0]) / (W - 1) * 2 - 1
    y = (ys + flow[:, 1]) / (H - 1) * 2 - 1
    return F.grid_sample(img, torch.stack([x, y], 3), mode="bilinear", padding_mode="zeros", align_corners=True)


def ssim_error(x, y):
    mu_x, mu_y = F.avg_pool2d(x, 3, 1, 1), F.avg_pool2d(y, 3, 1, 1)
    sx = F.avg_pool2d(x * x, 3, 1, 1) - mu_x ** 2
    sy = F.avg_pool2d(y * y, 3, 1, 1) - mu_y ** 2
    sxy = F.avg_pool2d(x * y, 3, 1, 1) - mu_x * mu_y
    n = (2 * mu_x * mu_y + 0.01 ** 2) * (2 * sxy + 0.03 ** 2)
    d = (mu_x ** 2 + mu_y ** 2 + 0.01 ** 2) * (sx + sy + 0.03 ** 2)
    return ((1 - n / d) / 2).clamp(0, 1)


def image_error(x, y, alpha=0.85):
    return alpha * ssim_error(x, y) + (1 - alpha) * (x - y).abs()


def smooth_loss(disp, img):
    dx, dy = disp[:, :, :, :-1] - disp[:, :, :, 1:], disp[:, :, :-1] - disp[:, :, 1:]
    wx = torch.exp(-(img[:, :, :, :-1] - img[:, :, :, 1:]).abs().mean(1, keepdim=True))
    wy = torch.exp(-(img[:, :, :-1] - img[:, :, 1:]).abs().mean(1, keepdim=True))
    return (dx * wx).abs().mean() + (dy * wy).abs().mean()


def stage1_loss(depth_net, pose_net, tgt, srcs, K, autocast, num_scales=4):
    """GeoNet's train_rigid loss of one batch (rigid_warp_weight 1, disp_smooth_weight 0.5)."""
    B, N = tgt.shape[0], len(srcs)
    with autocast():
        disps = depth_net(torch.cat([tgt] + srcs, 0))
        poses = pose_net(tgt, srcs)
    disps, poses = [d.float() for d in disps[:num_scales]], poses.float()
    loss = 0
    for s in range(num_scales):
        H, W = disps[s].shape[2:]
        scale = torch.tensor([[W / tgt.shape[3]], [H / tgt.shape[2]], [1.0]])
        Ks = K * scale
        t = F.interpolate(tgt, size=(H, W), mode="area") if s else tgt
        ss = [F.interpolate(x, size=(H, W), mode="area") if s else x for x in srcs]
        depth = 1 / disps[s]
        for i in range(N):
            fwd = rigid_flow(depth[:B], poses[:, i], Ks, False)
            bwd = rigid_flow(depth[B * (i + 1):B * (i + 2)], poses[:, i], Ks, True)
            loss = loss + N / 2 * (image_error(flow_warp(ss[i], fwd), t).mean() +
                                   image_error(flow_warp(t, bwd), ss[i]).mean())
        loss = loss + 0.5 / 2 ** s * smooth_loss(disps[s], torch.cat([t] + ss, 0))
    return loss


def timed(fn, warmup, iters):
    times = []
    cuda = torch.cuda.is_available() and torch.cuda.is_initialized()
    for i in range(warmup + iters):
        t0 = time.perf_counter()
        fn()
        if cuda:  # the kernels' time, not their launches'
            torch.cuda.synchronize()
        if i >= warmup:
            times.append(1e3 * (time.perf_counter() - t0))
    return times


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--row", choices=("depth", "step", "ceiling"), default="depth")
    ap.add_argument("--height", type=int, default=128)
    ap.add_argument("--width", type=int, default=416)
    ap.add_argument("--batch", type=int, default=0, help="default: 1 for depth, 4 for step")
    ap.add_argument("--threads", type=int, default=0, help="intra-op threads (0: PyTorch's default)")
    ap.add_argument("--device", default="cpu", help="cpu, or cuda (PyTorch >= 2.0: everything made on it)")
    ap.add_argument("--precision", choices=("fp32", "bf16"), default="fp32")
    ap.add_argument("--channels-last", action="store_true")
    ap.add_argument("--compile", action="store_true", help="torch.compile the networks (PyTorch >= 2.0)")
    ap.add_argument("--warmup", type=int, default=0, help="default: 5 for depth, 2 for step")
    ap.add_argument("--iters", type=int, default=9)
    ap.add_argument("--params-only", action="store_true")
    ap.add_argument("--export-onnx", default="", help="write the DepthNet (batch 1, --height x --width) as ONNX here and exit")
    a = ap.parse_args()
    if a.threads > 0:
        torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    if a.device != "cpu":
        torch.set_default_device(a.device)
    batch = a.batch or (4 if a.row == "step" else 1)
    warmup = a.warmup or (2 if a.row == "step" else 5)
    out = {"row": a.row, "device": a.device, "torch": torch.__version__, "threads": torch.get_num_threads(), "precision": a.precision,
           "channels_last": a.channels_last, "compile": a.compile, "batch": batch,
           "height": a.height, "width": a.width}
    if a.row == "ceiling":  # the best of 7 runs of a 2048 x 2048 product, as geo_bench measures it
        n = 2048
        for dtype, name in ((torch.float32, "fp32"), (torch.bfloat16, "bf16")):
            x, y = torch.rand(n, n).to(dtype), torch.rand(n, n).to(dtype)
            best = min(timed(lambda: torch.mm(x, y), 2, 7))
            out[f"ceiling_gflops_{name}"] = round(2 * n ** 3 / 1e9 / (best / 1e3), 1)
        print(json.dumps(out))
        return
    depth_net = DepthNet()
    out["params"] = sum(p.numel() for p in depth_net.parameters())
    if a.params_only:
        print(json.dumps(out))
        return
    if a.export_onnx:
        torch.onnx.export(depth_net.eval(), torch.rand(1, 3, a.height, a.width), a.export_onnx, input_names=["image"],
                          opset_version=13)
        out["onnx"] = a.export_onnx
        print(json.dumps(out))
        return
    if a.compile and not hasattr(torch, "compile"):
        sys.exit(f"torch.compile is not in PyTorch {torch.__version__}")
    fmt = torch.channels_last if a.channels_last else torch.contiguous_format
    bf16 = a.precision == "bf16"
    kind = a.device.split(":")[0]
    autocast = (lambda: torch.autocast(kind, dtype=torch.bfloat16)) if bf16 else contextlib.nullcontext
    img = torch.rand(batch, 3, a.height, a.width).contiguous(memory_format=fmt)
    if a.row == "depth":
        depth_net = depth_net.eval().to(memory_format=fmt)
        net = torch.compile(depth_net) if a.compile else depth_net
        with torch.inference_mode(), autocast():
            times = timed(lambda: net(img), warmup, a.iters)
    else:
        pose_net = PoseNet().to(memory_format=fmt)
        out["pose_params"] = sum(p.numel() for p in pose_net.parameters())
        depth_net = depth_net.train().to(memory_format=fmt)
        opt = torch.optim.Adam(list(depth_net.parameters()) + list(pose_net.parameters()), lr=2e-4)
        dnet = torch.compile(depth_net) if a.compile else depth_net
        pnet = torch.compile(pose_net) if a.compile else pose_net
        srcs = [torch.rand(batch, 3, a.height, a.width).contiguous(memory_format=fmt) for _ in range(2)]
        K = torch.tensor([[0.58 * a.width, 0, 0.5 * a.width], [0, 1.92 * a.height, 0.5 * a.height], [0, 0, 1]])

        def step():
            opt.zero_grad(set_to_none=True)
            loss = stage1_loss(dnet, pnet, img, srcs, K, autocast)
            loss.backward()
            opt.step()
            return loss

        times = timed(step, warmup, a.iters)
    out["median_ms"] = statistics.median(times)
    out["times_ms"] = [round(t, 2) for t in times]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
