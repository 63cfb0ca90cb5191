#!/usr/bin/env python3
"""The A-CycleGAN step of milv-train, written in plain PyTorch eager, timed beside ours.

Same networks (crates/milv-train/src/gan/nets.rs), same losses and order (generators and the
inverse-dynamics model in one backward pass against frozen discriminators, then both
discriminators on an image pool), batch 1, Adam, the same thread count, one process each,
in one run. Prints a Markdown table and writes JSON with --json.

Usage: tools/bench/train_step.sh [--size 128] [--steps 10] [--threads 2]
"""

import random
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

import torch_compare


def inorm(x):
    return F.instance_norm(x, eps=1e-5)


class Encoder(nn.Module):
    def __init__(self, w):
        super().__init__()
        a, b, c = w
        self.c0 = nn.Conv2d(3, a, 7, 1, 3, padding_mode="reflect")
        self.c1 = nn.Conv2d(a, b, 3, 2, 1)
        self.c2 = nn.Conv2d(b, c, 3, 2, 1)

    def forward(self, x):
        for c in (self.c0, self.c1, self.c2):
            x = F.relu(inorm(c(x)))
        return x


class Res(nn.Module):
    def __init__(self, c):
        super().__init__()
        self.a = nn.Conv2d(c, c, 3, 1, 1, padding_mode="reflect")
        self.b = nn.Conv2d(c, c, 3, 1, 1, padding_mode="reflect")

    def forward(self, x):
        return x + inorm(self.b(F.relu(inorm(self.a(x)))))


class Generator(nn.Module):
    def __init__(self, w=(16, 32, 64), blocks=4):
        super().__init__()
        a, b, c = w
        self.enc = Encoder(w)
        self.res = nn.ModuleList([Res(c) for _ in range(blocks)])
        self.up0 = nn.ConvTranspose2d(c, b, 3, 2, 1, output_padding=1)
        self.up1 = nn.ConvTranspose2d(b, a, 3, 2, 1, output_padding=1)
        self.out = nn.Conv2d(a, 3, 7, 1, 3, padding_mode="reflect")

    def forward(self, x):
        h = self.enc(x)
        for r in self.res:
            h = r(h)
        h = F.relu(inorm(self.up0(h)))
        h = F.relu(inorm(self.up1(h)))
        return torch.tanh(self.out(h))


class Discriminator(nn.Module):
    def __init__(self, w=64):
        super().__init__()
        self.c = nn.ModuleList(
            [
                nn.Conv2d(3, w, 4, 2, 1),
                nn.Conv2d(w, 2 * w, 4, 2, 1),
                nn.Conv2d(2 * w, 4 * w, 4, 2, 1),
                nn.Conv2d(4 * w, 8 * w, 4, 1, 1),
                nn.Conv2d(8 * w, 1, 4, 1, 1),
            ]
        )

    def forward(self, x):
        for i, c in enumerate(self.c):
            x = c(x)
            if i == 0:
                x = torch.maximum(x, 0.2 * x)
            elif i < len(self.c) - 1:
                x = inorm(x)
                x = torch.maximum(x, 0.2 * x)
        return x


def spatial_softmax(x):
    b, c, h, w = x.shape
    p = torch.softmax(x.view(b, c, h * w), -1).view(b, c, h, w)
    xs = torch.linspace(-1, 1, w).view(1, 1, 1, w)
    ys = torch.linspace(-1, 1, h).view(1, 1, h, 1)
    return torch.cat([(p * xs).sum((2, 3)), (p * ys).sum((2, 3))], 1)


class InverseDynamics(nn.Module):
    def __init__(self, z=64, f=16, hidden=100, action=2):
        super().__init__()
        self.c0 = nn.Conv2d(2 * z, f, 5, 2, 2)
        self.c1 = nn.Conv2d(f, f, 5, 1, 2)
        self.fc0 = nn.Linear(2 * f, hidden)
        self.fc1 = nn.Linear(hidden, hidden)
        self.out = nn.Linear(hidden, action)

    def forward(self, zt, zn):
        h = F.relu(self.c1(F.relu(self.c0(torch.cat([zt, zn], 1)))))
        h = spatial_softmax(h)
        return self.out(F.relu(self.fc1(F.relu(self.fc0(h)))))


class Pool:
    def __init__(self, n=50):
        self.n, self.images = n, []

    def query(self, batch):
        out = []
        for img in batch:
            img = img.detach().clone()
            if len(self.images) < self.n:
                self.images.append(img)
                out.append(img)
            elif random.random() < 0.5:
                k = random.randrange(len(self.images))
                out.append(self.images[k])
                self.images[k] = img
            else:
                out.append(img)
        return torch.stack(out)


def mse_to(pred, v):
    return F.mse_loss(pred, torch.full_like(pred, v))


def bench_torch(size, warmup, steps):
    torch.manual_seed(0)
    G, Fn, DX, DY, I = Generator(), Generator(), Discriminator(), Discriminator(), InverseDynamics()
    opt = lambda m, lr, b1: torch.optim.Adam(m.parameters(), lr=lr, betas=(b1, 0.999))
    og, of, odx, ody, oi = opt(G, 2e-4, 0.5), opt(Fn, 2e-4, 0.5), opt(DX, 2e-4, 0.5), opt(DY, 2e-4, 0.5), opt(I, 0.01, 0.9)
    px, py = Pool(), Pool()
    img = lambda: torch.rand(1, 3, size, size) * 2 - 1
    x, y, ph, pr, yt, yt1 = (img() for _ in range(6))
    a = torch.full((1, 2), 0.5)

    def step():
        for d in (DX, DY):
            d.requires_grad_(False)
        for o in (og, of, oi):
            o.zero_grad()
        fake_y, fake_x = G(x), Fn(y)
        gan = mse_to(DY(fake_y), 1.0) + mse_to(DX(fake_x), 1.0)
        cyc = (Fn(fake_y) - x).abs().mean() + (G(fake_x) - y).abs().mean()
        aux = (G(ph) - pr).abs().mean() + (Fn(pr) - ph).abs().mean()
        idm = F.mse_loss(I(Fn.enc(yt), Fn.enc(yt1)), a)
        (gan + 10.0 * cyc + aux + idm).backward()
        og.step(); of.step(); oi.step()
        for d in (DX, DY):
            d.requires_grad_(True)
        odx.zero_grad(); ody.zero_grad()
        old_y, old_x = py.query(fake_y), px.query(fake_x)
        d_y = 0.5 * (mse_to(DY(y), 1.0) + mse_to(DY(old_y), 0.0))
        d_x = 0.5 * (mse_to(DX(x), 1.0) + mse_to(DX(old_x), 0.0))
        (d_x + d_y).backward()
        odx.step(); ody.step()

    for _ in range(warmup):
        step()
    ms = []
    for _ in range(steps):
        t = time.perf_counter()
        step()
        ms.append((time.perf_counter() - t) * 1e3)
    return ms


def main():
    ap = torch_compare.parser(__doc__)
    ap.add_argument("--size", type=int, default=128)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    mine = torch_compare.ours(a, "bench-step", "--size", str(a.size))
    theirs = bench_torch(a.size, a.warmup, a.steps)
    r = torch_compare.row(a, mine, theirs, size=a.size)
    print("| size | threads | milv-train median ms | PyTorch eager median ms | milv / PyTorch |")
    print("|---:|---:|---:|---:|---:|")
    print(f"| {a.size} | {a.threads} | {r['milv_median_ms']:.1f} | {r['torch_median_ms']:.1f} | {r['ratio_median']:.2f}× |")


if __name__ == "__main__":
    sys.exit(main())
