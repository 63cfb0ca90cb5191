#!/usr/bin/env python3
"""The second-order meta step of milv-train, written in plain PyTorch eager, timed beside ours.

Same policy (crates/milv-train/src/meta/policy.rs): convolutions of 16 5×5 filters (latents:
strides 2, 2, 1; images: 2, 2, 2, 1, 1, 1), spatial softmax, three hidden layers of 100,
a pre-update head of 20 read by the learned loss L_ψ (temporal convolutions 10, 10, 1
with 10 filters, squared output), a post-update action head; one inner step
θ' = θ − α ∇_θ L_ψ with create_graph (second order), per-frame weighted behaviour
cloning after it, Adam on θ and ψ. Same tasks × frames, same threads, one process each.

Usage: tools/bench/meta_step.sh [--input latent|image] [--size 128] [--tasks 4] [--frames 50]
"""

import sys
import time

import torch
import torch.nn.functional as F

import torch_compare


def uniform(shape, fan_in):
    b = 1.0 / fan_in ** 0.5
    return (torch.rand(shape) * 2 * b - b).requires_grad_()


def make(input_shape, strides):
    c, f, k = input_shape[0], 16, 5
    theta, psi = [], []
    for _ in strides:
        theta += [uniform((f, c, k, k), c * k * k), uniform((f,), c * k * k)]
        c = f
    d = 2 * f
    for _ in range(3):
        theta += [uniform((100, d), d), uniform((100,), d)]
        d = 100
    theta += [uniform((20, d), d), uniform((20,), d), uniform((2, d), d), uniform((2,), d)]
    for ci, co, kk in [(20, 10, 10), (10, 10, 10), (10, 2, 1)]:
        psi += [uniform((co, ci, kk), ci * kk), uniform((co,), ci * kk)]
    return theta, psi


def spatial_softmax(x):
    b, c, h, w = x.shape
    p = x.view(b, c, h * w).softmax(-1).view(b, c, h, w)
    xs = torch.linspace(-1, 1, w).view(1, 1, 1, w)
    ys = torch.linspace(-1, 1, h).view(1, 1, h, 1)
    return torch.cat([(p * xs).sum((2, 3)), (p * ys).sum((2, 3))], 1)


def trunk(th, x, strides):
    for i, s in enumerate(strides):
        x = F.relu(F.conv2d(x, th[2 * i], th[2 * i + 1], stride=s, padding=2))
    h = spatial_softmax(x)
    b = 2 * len(strides)
    for j in range(3):
        h = F.relu(F.linear(h, th[b + 2 * j], th[b + 2 * j + 1]))
    return h


def adaptation_loss(th, psi, x, strides):
    h = F.linear(trunk(th, x, strides), th[-4], th[-3]).t().unsqueeze(0)
    for i in range(3):
        h = F.conv1d(h, psi[2 * i], psi[2 * i + 1])
        if i < 2:
            h = F.relu(h)
    return h.square().mean()


def meta_step(theta, psi, opt, tasks, strides, alpha=0.01):
    opt.zero_grad()
    total = 0
    for inner, outer, actions, weights in tasks:
        li = adaptation_loss(theta, psi, inner, strides)
        grads = torch.autograd.grad(li, theta[:-2], create_graph=True)
        adapted = [t - alpha * g for t, g in zip(theta[:-2], grads)] + theta[-2:]
        pred = F.linear(trunk(adapted, outer, strides), adapted[-2], adapted[-1])
        err = (pred - actions).square().mean(1)
        total = total + (err * weights).mean()
    loss = total / len(tasks)
    loss.backward()
    opt.step()
    return loss.item()


def bench_torch(input_kind, size, tasks, frames, warmup, steps):
    torch.manual_seed(0)
    if input_kind == "latent":
        shape, strides = (64, size // 4, size // 4), [2, 2, 1]
    else:
        shape, strides = (3, size, size), [2, 2, 2, 1, 1, 1]
    theta, psi = make(shape, strides)
    opt = torch.optim.Adam(theta + psi, lr=1e-3)
    batch = [(torch.randn(frames, *shape), torch.randn(frames, *shape), torch.randn(frames, 2),
              torch.rand(frames)) for _ in range(tasks)]
    for _ in range(warmup):
        meta_step(theta, psi, opt, batch, strides)
    ms = []
    for _ in range(steps):
        t = time.perf_counter()
        meta_step(theta, psi, opt, batch, strides)
        ms.append((time.perf_counter() - t) * 1e3)
    return ms


def main():
    ap = torch_compare.parser(__doc__)
    ap.add_argument("--input", default="latent", choices=["latent", "image"])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--tasks", type=int, default=4)
    ap.add_argument("--frames", type=int, default=50)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    mine = torch_compare.ours(a, "bench-meta", "--input", a.input, "--size", str(a.size),
                              "--tasks", str(a.tasks), "--frames", str(a.frames))
    theirs = bench_torch(a.input, a.size, a.tasks, a.frames, a.warmup, a.steps)
    r = torch_compare.row(a, mine, theirs, input=a.input, size=a.size, tasks=a.tasks, frames=a.frames)
    print("| input | size | tasks × frames | threads | milv-train median ms | PyTorch eager median ms | milv / PyTorch |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    print(f"| {a.input} | {a.size} | {a.tasks} × {a.frames} | {a.threads} | {r['milv_median_ms']:.1f} | "
          f"{r['torch_median_ms']:.1f} | {r['ratio_median']:.2f}× |")


if __name__ == "__main__":
    sys.exit(main())
