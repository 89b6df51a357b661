"""geo's networks written in plain torch.nn, loading geo.state_dicts(): DepthNet and FlowNet (ResNet
encoder-decoders with feature refinement, FR) and PoseNet, as PyTorch users write them. An
independent implementation of the C++ networks (tests/python/test_nn.py: the same outputs), and the
way to geo's weights in PyTorch tools (torch.onnx.export, torch.compile, fine-tuning):

    import geo, geo.nn
    nets = geo.nn.from_checkpoint("model.pt")   # {"depth", "pose", "flow"}: eval-mode modules
    disp = nets["depth"](image)[0]              # image [B,3,H,W] in [0,1] -> finest disparity
    torch.onnx.export(nets["depth"], image, "depth.onnx")
"""
import torch
import torch.nn as nn
import torch.nn.functional as F

import geo


class Conv2d(nn.Conv2d):
    """nn.Conv2d computed as geo's convolutions are: with the zero input channels geo appends where the
    oneDNN of LibTorch 2.x computes a channel count wrongly on the CPU (33 or 129 input channels gave
    errors of 15 and NaN in Debian's PyTorch 2.6.0+dfsg-7+b1; geo._geo.onednn_channel_padding is the
    rule). The same convolution exactly; nothing appended while tracing or exporting."""

    def forward(self, x):
        tracing = torch.jit.is_tracing() or torch.onnx.is_in_onnx_export()
        n = 0 if tracing or self.groups != 1 else geo._geo.onednn_channel_padding(x)
        if n == 0:
            return super().forward(x)
        w = F.pad(self.weight, (0, 0, 0, 0, 0, n))
        x = F.pad(x, (0, 0, 0, 0, 0, n))
        return F.conv2d(x, w, self.bias, self.stride, self.padding, self.dilation, self.groups)


class ConvBn(nn.Module):
    """k x k conv (stride, padding k // 2, no bias) -> BatchNorm -> ReLU (optional)."""

    def __init__(self, cin, cout, k, stride=1, relu=True, eps=1e-3):
        super().__init__()
        self.conv = Conv2d(cin, cout, k, stride, k // 2, bias=False)
        self.bn = nn.BatchNorm2d(cout, eps=eps)
        self.relu = relu

    def forward(self, x):
        y = self.bn(self.conv(x))
        return F.relu(y) if self.relu else y


class FeatureRefinement(nn.Module):
    """CBAM: channel attention (a shared MLP on the average- and max-pooled features), then spatial
    attention (a 7x7 conv on the channel-wise max and mean)."""

    def __init__(self, channels, ratio=16, kernel=7, spatial_bn=False, eps=1e-3):
        super().__init__()
        hidden = max(1, channels // ratio)
        self.mlp_in = Conv2d(channels, hidden, 1, bias=False)
        self.mlp_out = Conv2d(hidden, channels, 1, bias=False)
        self.spatial = Conv2d(2, 1, kernel, padding=kernel // 2, bias=False)
        self.spatial_bn = nn.BatchNorm2d(1, eps=eps) if spatial_bn else None

    def forward(self, x):
        def mlp(t):
            return self.mlp_out(F.relu(self.mlp_in(t)))

        f1 = x * torch.sigmoid(mlp(x.mean((2, 3), keepdim=True)) + mlp(x.amax((2, 3), keepdim=True)))
        a = self.spatial(torch.cat([f1.amax(1, keepdim=True), f1.mean(1, keepdim=True)], 1))
        if self.spatial_bn is not None:
            a = self.spatial_bn(a)
        return f1 * torch.sigmoid(a)


class Bottleneck(nn.Module):
    """GeoNet's resconv: 1x1 -> 3x3/stride -> 1x1 (4n) plus a projection shortcut, then ReLU."""

    def __init__(self, cin, n, stride, eps):
        super().__init__()
        self.conv1 = ConvBn(cin, n, 1, eps=eps)
        self.conv2 = ConvBn(n, n, 3, stride, eps=eps)
        self.conv3 = ConvBn(n, 4 * n, 1, relu=False, eps=eps)
        self.shortcut = ConvBn(cin, 4 * n, 1, stride, relu=False, eps=eps)

    def forward(self, x):
        return F.relu(self.conv3(self.conv2(self.conv1(x))) + self.shortcut(x))


class BasicBlock(nn.Module):
    """ResNet-18/34 block: 3x3/stride -> 3x3 plus the shortcut (a projection where the shape changes)."""

    def __init__(self, cin, n, stride, eps):
        super().__init__()
        self.conv1 = ConvBn(cin, n, 3, stride, eps=eps)
        self.conv2 = ConvBn(n, n, 3, relu=False, eps=eps)
        self.shortcut = ConvBn(cin, n, 1, stride, relu=False, eps=eps) if cin != n or stride != 1 else None

    def forward(self, x):
        return F.relu(self.conv2(self.conv1(x)) + (x if self.shortcut is None else self.shortcut(x)))


class Encoder(nn.Module):
    """ResNet-18/34/50 with the stride in the last block of each stage (GeoNet) and FR after each stage."""

    def __init__(self, cin, depth=50, fr=True, fr_ratio=16, fr_spatial_bn=False, eps=1e-3):
        super().__init__()
        blocks = {18: (2, 2, 2, 2), 34: (3, 4, 6, 3), 50: (3, 4, 6, 3)}[depth]
        block = Bottleneck if depth == 50 else BasicBlock
        self.conv1 = ConvBn(cin, 64, 7, 2, eps=eps)
        self.channels = [64, 64]
        width_in = 64
        for s, (width, count) in enumerate(zip((64, 128, 256, 512), blocks)):
            layers = []
            for b in range(count):
                layers.append(block(width_in, width, 2 if b == count - 1 else 1, eps))
                width_in = 4 * width if depth == 50 else width
            setattr(self, f"stage{s + 1}", nn.Sequential(*layers))
            if fr:
                setattr(self, f"refined{s + 1}", FeatureRefinement(width_in, fr_ratio, spatial_bn=fr_spatial_bn, eps=eps))
            self.channels.append(width_in)
        self.fr = fr

    def forward(self, x):
        feats = [self.conv1(x)]
        feats.append(F.max_pool2d(feats[-1], 3, 2, 1))
        for s in range(1, 5):
            y = getattr(self, f"stage{s}")(feats[-1])
            feats.append(getattr(self, f"refined{s}")(y) if self.fr else y)
        return feats


def _resize_like(x, ref):
    # Nearest to ref's size, unconditionally (the same pixels when the sizes agree), so that tracers
    # (torch.fx, torch.onnx) see no branch on a shape.
    return F.interpolate(x, size=ref.shape[2:], mode="nearest")


def _upsample2(x, mode):
    if mode == "bilinear":
        return F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)
    return F.interpolate(x, scale_factor=2.0, mode="nearest")


class EncoderDecoder(nn.Module):
    """The paper's encoder-decoder: six decoder stages (upconv, skip from the encoder, iconv, FR) and
    predictions at the last four, each fed upsampled to the next; `head` maps the raw prediction."""

    WIDTHS = (512, 256, 128, 64, 32, 16)

    def __init__(self, cin, cout, head, model):
        super().__init__()
        fr = model["use_fr"]
        eps = model["bn_eps"]
        self.encoder = Encoder(cin, model["encoder_depth"], fr and model["fr_encoder"], model["fr_ratio"],
                               model["fr_spatial_bn"], eps)
        self.fr_decoder = fr and model["fr_decoder"]
        self.upsample = model["upsample"]
        self.head = head
        enc = self.encoder.channels
        width_in = enc[5]
        for k, width in enumerate(self.WIDTHS):
            name = str(6 - k)
            setattr(self, "upconv" + name, ConvBn(width_in, width, 3, eps=eps))
            cat = width + (enc[4 - k] if k < 5 else 0) + (cout if k >= 3 else 0)
            setattr(self, "iconv" + name, ConvBn(cat, width, 3, eps=eps))
            if self.fr_decoder:
                setattr(self, f"refined{k + 5}", FeatureRefinement(width, model["fr_ratio"],
                                                                   spatial_bn=model["fr_spatial_bn"], eps=eps))
            if k >= 2:
                setattr(self, "pred" + name, Conv2d(width, cout, 3, padding=1))
            width_in = width

    def forward(self, x):
        feats = self.encoder(x)
        y, preds = feats[5], []
        for k in range(6):
            name = str(6 - k)
            ref = feats[4 - k] if k < 5 else x
            parts = [_resize_like(getattr(self, "upconv" + name)(_upsample2(y, self.upsample)), ref)]
            if k < 5:
                parts.append(feats[4 - k])
            if k >= 3:
                parts.append(_resize_like(_upsample2(preds[-1], self.upsample), ref))
            y = getattr(self, "iconv" + name)(torch.cat(parts, 1))
            if self.fr_decoder:
                y = getattr(self, f"refined{k + 5}")(y)
            if k >= 2:
                preds.append(self.head(getattr(self, "pred" + name)(y)))
        return preds[::-1]


class DepthNet(nn.Module):
    """Image [B,3,H,W] in [0,1] -> disparities at 4 scales (finest first), 5 sigmoid + 0.01; depth = 1 / disp."""

    def __init__(self, model):
        super().__init__()
        self.net = EncoderDecoder(3, 1, lambda t: 5 * torch.sigmoid(t) + 0.01, model)

    def forward(self, image):
        return self.net(image * 2 - 1)


class FlowNet(nn.Module):
    """The FlowNet's 12-channel input (target, source and rigidly warped source in [-1,1], rigid flow,
    normalised rigid error) -> residual flows in pixels at 4 scales (finest first)."""

    def __init__(self, model):
        super().__init__()
        self.net = EncoderDecoder(12, 2, lambda t: 0.1 * t, model)

    def forward(self, x):
        flows = []
        for f in self.net(x):
            flows.append(f * torch.tensor([f.shape[3], f.shape[2]], dtype=f.dtype).view(1, 2, 1, 1))
        return flows


class PoseNet(nn.Module):
    """Target and sources [B,3,H,W] in [0,1] -> [B,N,6] (tx, ty, tz, rx, ry, rz): seven strided
    conv + BatchNorm + ReLU layers, a 1x1 conv averaged over the image, x 0.01 (GeoNet)."""

    def __init__(self, seq_length, eps=1e-3, learn_intrinsics=False):
        super().__init__()
        self.sources = seq_length - 1
        cin = 3 * seq_length
        for i, (cout, k) in enumerate(zip((16, 32, 64, 128, 256, 256, 256), (7, 5, 3, 3, 3, 3, 3))):
            setattr(self, f"conv{i + 1}", ConvBn(cin, cout, k, 2, eps=eps))
            cin = cout
        self.pred = Conv2d(256, 6 * self.sources, 1)
        self.intrinsics = Conv2d(256, 4, 1) if learn_intrinsics else None

    def forward(self, target, sources):
        x = torch.cat([target, *sources], 1) * 2 - 1
        for i in range(7):
            x = getattr(self, f"conv{i + 1}")(x)
        return 0.01 * self.pred(x).mean((2, 3)).view(-1, self.sources, 6)


def from_checkpoint(path):
    """geo's networks of a checkpoint, run folder or model file as eval-mode torch.nn modules:
    {"depth": DepthNet, "pose": PoseNet, "flow": FlowNet or None}."""
    states = geo.state_dicts(path)
    model = states["spec"]["model"]
    nets = {"depth": DepthNet(model),
            "pose": PoseNet(states["spec"]["data"]["seq_length"], model["bn_eps"], model["learn_intrinsics"]),
            "flow": FlowNet(model) if states["flow"] is not None else None}
    for name, net in nets.items():
        if net is not None:
            net.load_state_dict(states[name])
            net.eval()
    return nets
