#!/usr/bin/env python3
"""PyTorch twins of evalharness's own shipped Push-T networks, for the roofline table in
BENCHMARKS.md: their FLOPs and PyTorch's time at their shapes, beside `cargo bench --bench models`.

The shipped networks (the frame decoder, the latent world model's U-Net, the diffusion policy)
exist only in evalharness; no PyTorch implementation of them exists to time. A twin has the same
layers, widths, kernel sizes and map sizes (from the shipped configs, read below), with random
weights (the cost does not depend on them), built from the fixture re-implementations beside
this script where they have the layer (`fixtures/driftworld_wm.py`'s U-Net blocks,
`fixtures/gpc_policy.py`'s 1-D U-Net). So its FLOPs (PyTorch's FlopCounterMode: convolutions and
matrix products, a multiply-add counted as 2) are the network's, and its time is PyTorch's for
the same work, not a check of evalharness's numbers. CI never runs this.

    python scripts/roofline_torch.py [--threads N] [--only decoder,world_model,policy]

Each case is timed as the evalharness benchmark of the same name times its network:
- `decoder` (`decoder/direct/50`): 50 latents `[8, 12, 12]` decoded to 96² frames;
- `world_model` (`world_model_chunk/predict_4_decode_2/{1,100}`): one drifting pass of the U-Net over
  a chunk of 4 frames (history 4, the anchor and the action map as input channels) and 2 of
  the 4 predicted frames decoded, per sample;
- `policy` (`policy_decision/{1,100}`): the frame encoder on 2 frames, then 10 DDIM steps of
  the 1-D U-Net (horizon 16), per episode.
"""
import argparse
import json
import os
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F
from torch.utils.flop_counter import FlopCounterMode

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "fixtures"))
import driftworld_wm as dw  # noqa: E402
import gpc_policy as gp  # noqa: E402

ROOT = os.path.dirname(HERE)


def shipped(path):
    with open(os.path.join(ROOT, path)) as f:
        return json.load(f)


def conv(cin, cout, stride=1):
    return nn.Conv2d(cin, cout, 3, stride, 1)


class Res2d(nn.Module):
    """GroupNorm → SiLU → 3×3 conv, twice, plus the input (the autoencoder's and the policy
    encoder's residual block)."""

    def __init__(self, c, groups):
        super().__init__()
        self.n1, self.c1, self.n2, self.c2 = nn.GroupNorm(groups, c), conv(c, c), nn.GroupNorm(groups, c), conv(c, c)

    def forward(self, x):
        return x + self.c2(F.silu(self.n2(self.c1(F.silu(self.n1(x))))))


class Decoder(nn.Module):
    """The autoencoder's decoder: 3×3 in, a block at 12², then three times nearest 2× up, a 3×3
    conv and a block; GroupNorm, SiLU, 3×3 to RGB."""

    def __init__(self, latent, channels, groups):
        super().__init__()
        c0, c1, c2, c3 = channels
        self.inp = conv(latent, c3)
        self.blocks = nn.ModuleList([Res2d(c, groups) for c in (c3, c2, c1, c0)])
        self.ups = nn.ModuleList([conv(c3, c2), conv(c2, c1), conv(c1, c0)])
        self.norm, self.out = nn.GroupNorm(groups, c0), conv(c0, 3)

    def forward(self, z):
        h = self.blocks[0](self.inp(z))
        for up, block in zip(self.ups, self.blocks[1:]):
            h = block(up(F.interpolate(h, scale_factor=2, mode="nearest")))
        return self.out(F.silu(self.norm(h)))


class LatentUNet(nn.Module):
    """The shipped world model's U-Net: driftworld_wm.py's blocks at the shipped widths, levels
    and attention rates, its first and last convolutions widened to the latent channels (the
    noisy chunk, the history, the anchor and the action map in; the chunk's latents out)."""

    def __init__(self, u):
        super().__init__()
        self.net = dw.WorldUNet(u["model_channels"], tuple(u["channel_mult"]), u["res_blocks"],
                                tuple(u["attention_rates"]), history=u["history"], emb=u["emb_dim"],
                                head_channels=u["head_dim"])
        c = u["frame_channels"]
        self.in_ch = c * (1 + u["history"] + int(u["anchor"])) + int(u["action_maps"])
        self.net.input_blocks[0] = dw.Seq([dw.FactorConv(self.in_ch, u["model_channels"] * u["channel_mult"][0])])
        self.net.out[2] = dw.FactorConv(u["model_channels"] * u["channel_mult"][0], c)

    def forward(self, x, actions):  # x: [b, in_ch, f, s, s]
        return self.net.trunk(x, actions)


class ObsEncoder(nn.Module):
    """The policy's frame encoder: four stride-2 3×3 convs (96² → 6²), a block after each of the
    first three, GroupNorm, SiLU, a linear layer to the features."""

    def __init__(self, w, feature_dim, image_size):
        super().__init__()
        chans = [3, w, 2 * w, 4 * w, 4 * w]
        self.downs = nn.ModuleList([conv(chans[i], chans[i + 1], 2) for i in range(4)])
        self.blocks = nn.ModuleList([Res2d(chans[i], max(chans[i] // 8, 1)) for i in range(1, 4)])
        self.norm = nn.GroupNorm(max(4 * w // 8, 1), 4 * w)
        self.out = nn.Linear(4 * w * (image_size // 16) ** 2, feature_dim)

    def forward(self, x):
        h = x
        for i, down in enumerate(self.downs):
            h = down(h)
            if i < len(self.blocks):
                h = self.blocks[i](h)
        return self.out(F.silu(self.norm(h)).flatten(1))


def decoder_case(b):
    cfg = shipped("checkpoints/pusht/autoencoder/config.json")["model"]
    dec = Decoder(cfg["latent_channels"], cfg["channels"], cfg["groups"]).eval()
    z = torch.randn(b, cfg["latent_channels"], 12, 12)
    return f"decoder/{b}", lambda: dec(z), b


def world_model_case(b):
    wm = shipped("checkpoints/pusht/world_model/config.json")["model"]
    ae = shipped("checkpoints/pusht/autoencoder/config.json")["model"]
    unet = LatentUNet(wm["unet"]).eval()
    dec = Decoder(ae["latent_channels"], ae["channels"], ae["groups"]).eval()
    c, s, f = wm["unet"]["frame_channels"], wm["latents"]["size"], wm["future"]
    x, actions = torch.randn(b, unet.in_ch, f, s, s), torch.rand(b, f, 2) * 2 - 1

    def run():
        out = unet(x, actions)  # [b, c, f, s, s]
        return dec(out[:, :, f - 2:].transpose(1, 2).reshape(2 * b, c, s, s))

    return f"world_model_chunk/predict_4_decode_2/{b}", run, b


def policy_case(b):
    dirs = sorted(d for d in os.listdir(os.path.join(ROOT, "checkpoints/pusht/policies")) if d.startswith("epoch"))
    cfg = shipped(os.path.join("checkpoints/pusht/policies", dirs[0], "policy.json"))["config"]
    n = cfg["net"]
    enc = ObsEncoder(n["encoder_width"], n["feature_dim"], n["image_size"]).eval()
    cond_obs = n["obs_horizon"] * (n["feature_dim"] + 2)
    unet = gp.Unet1d(n["action_dim"], cond_obs, n["step_embed"], n["down_dims"], n["kernel"]).eval()
    frames = torch.rand(b * n["obs_horizon"], 3, n["image_size"], n["image_size"]) * 2 - 1
    pos = torch.rand(b, n["obs_horizon"], 2) * 2 - 1
    x = torch.randn(b, cfg["horizon"], n["action_dim"])

    def run():
        f = enc(frames).reshape(b, n["obs_horizon"], -1)
        obs = torch.cat([f, pos], -1).flatten(1)
        y = x
        for t in range(cfg["inference_steps"]):
            y = unet(y, torch.full((b,), 90 - 10 * t), obs)
        return y

    return f"policy_decision/{b}", run, b


def measure(name, run, per, threads):
    with torch.no_grad():
        with FlopCounterMode(display=False) as fc:
            run()
        flops = fc.get_total_flops()
        run()  # warm-up
        times = []
        for _ in range(5):
            t = time.perf_counter()
            run()
            times.append(time.perf_counter() - t)
    best = min(times)
    print(f"{name}: {flops / 1e9:.3f} GFLOP ({flops / per / 1e6:.1f} MFLOP per item); torch {torch.__version__}, "
          f"{threads} threads: {best * 1e3:.1f} ms (best of 5) = {flops / best / 1e9:.1f} GFLOP/s")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=torch.get_num_threads())
    ap.add_argument("--only", default="decoder,world_model,policy")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    cases = {"decoder": [(decoder_case, 50)], "world_model": [(world_model_case, 1), (world_model_case, 100)],
             "policy": [(policy_case, 1), (policy_case, 100)]}
    for key in a.only.split(","):
        for make, b in cases[key]:
            name, run, per = make(b)
            measure(name, run, per, a.threads)


if __name__ == "__main__":
    main()
