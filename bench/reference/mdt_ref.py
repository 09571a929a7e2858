#!/usr/bin/python3
"""SimMotionEdit's Motion Diffusion Transformer (REFERENCE 3.2) in PyTorch Python: the same
architecture as plugins/mdt_editor (learned text encoder pooled and projected; condition transformer
over [text token; source frames]; similarity head; DiT blocks with adaLN-Zero over [enhanced source;
separator; noisy target]; x0 prediction; grouped masked MSE + 0.05 weighted cross-entropy), trained
on the batch bench/mdt_bench writes, with AdamW and gradient clipping, timed.

  /usr/bin/python3 bench/reference/mdt_ref.py --batch-dir DIR --dim 128 --cond-layers 2 --layers 4 \
      --heads 4 --ff 256 --steps 5 --threads 1
prints one JSON line: {"samples_per_second": ..., "seconds": ..., "loss": ...}
"""
import argparse
import math
import os

import numpy as np
import torch
from torch import nn
import torch.nn.functional as F

# The shared layers and timing loop of the TEMOS reference (same directory).
from temos_ref import encoder, positional_encoding, report_timed_steps

GROUPS = [(0, 3), (3, 9), (9, 15), (15, 141), (141, 207)]


def timestep_embedding(t, dim=256):
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, dtype=torch.float32) / half)
    args = t.float().unsqueeze(1) * freqs.unsqueeze(0)
    return torch.cat([torch.cos(args), torch.sin(args)], 1)


class DiTBlock(nn.Module):
    def __init__(self, dim, heads, ff):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, elementwise_affine=False, eps=1e-6)
        self.attn = nn.MultiheadAttention(dim, heads, dropout=0.0)
        self.norm2 = nn.LayerNorm(dim, elementwise_affine=False, eps=1e-6)
        self.fc1 = nn.Linear(dim, ff)
        self.fc2 = nn.Linear(ff, dim)
        self.modulation = nn.Linear(dim, 6 * dim)
        nn.init.zeros_(self.modulation.weight)
        nn.init.zeros_(self.modulation.bias)

    def forward(self, x, c, padding):
        shift1, scale1, gate1, shift2, scale2, gate2 = self.modulation(F.silu(c)).unsqueeze(0).chunk(6, dim=2)
        h = self.norm1(x) * (1 + scale1) + shift1
        x = x + gate1 * self.attn(h, h, h, key_padding_mask=padding, need_weights=False)[0]
        h = self.norm2(x) * (1 + scale2) + shift2
        return x + gate2 * self.fc2(F.gelu(self.fc1(h), approximate="tanh"))


class Mdt(nn.Module):
    def __init__(self, a):
        super().__init__()
        d, text_dim = a.dim, min(a.dim, 256)
        self.dim = d
        self.text_dim = text_dim
        self.embed = nn.Embedding(a.vocab + 2, text_dim, padding_idx=0)
        self.text_encoder = encoder(text_dim, a.heads, a.ff, a.dropout, 1)
        self.text_proj = nn.Linear(text_dim, d)
        self.source_in = nn.Linear(207, d)
        self.target_in = nn.Linear(207, d)
        self.out = nn.Linear(d, 207)
        self.time_mlp = nn.Sequential(nn.Linear(256, d), nn.SiLU(), nn.Linear(d, d))
        self.separator = nn.Parameter(torch.randn(d) * 0.02)
        self.condition = encoder(d, a.heads, a.ff, a.dropout, a.cond_layers)
        self.sim_head = nn.Sequential(nn.Linear(d, a.ff), nn.SiLU(), nn.Linear(a.ff, a.ff), nn.SiLU(), nn.Linear(a.ff, 3))
        self.blocks = nn.ModuleList([DiTBlock(d, a.heads, a.ff) for _ in range(a.layers)])
        self.final_norm = nn.LayerNorm(d, elementwise_affine=False, eps=1e-6)
        self.final_modulation = nn.Linear(d, 2 * d)
        nn.init.zeros_(self.final_modulation.weight)
        nn.init.zeros_(self.final_modulation.bias)

    def forward(self, xt, t, target_padding, tokens, source, source_padding, drop_text, drop_source):
        n, ts, tt = xt.shape[1], source.shape[0], xt.shape[0]
        text_padding = tokens.eq(0)
        x = self.embed(tokens).transpose(0, 1) * math.sqrt(self.text_dim) + positional_encoding(tokens.shape[1], self.text_dim)
        text_tokens = self.text_proj(self.text_encoder(x, src_key_padding_mask=text_padding))
        keep = (~text_padding).t().unsqueeze(2).float()
        text = (text_tokens * keep).sum(0) / keep.sum(0).clamp_min(1.0)
        text = text * (1 - drop_text.float().view(-1, 1))
        source_padding = source_padding | drop_source.view(-1, 1)
        src = self.source_in(source) * (1 - drop_source.float().view(1, -1, 1))
        h = torch.cat([text.unsqueeze(0), src], 0) + positional_encoding(ts + 1, self.dim)
        h = self.condition(h, src_key_padding_mask=torch.cat([torch.zeros(n, 1, dtype=torch.bool), source_padding], 1))
        enhanced_text, enhanced_source = h[0], h[1:]
        similarity = self.sim_head(enhanced_source).transpose(0, 1)
        cond = self.time_mlp(timestep_embedding(t)) + enhanced_text
        x = torch.cat([enhanced_source, self.separator.view(1, 1, -1).expand(1, n, self.dim), self.target_in(xt)], 0)
        x = x + positional_encoding(ts + 1 + tt, self.dim)
        padding = torch.cat([source_padding, torch.zeros(n, 1, dtype=torch.bool), target_padding], 1)
        for block in self.blocks:
            x = block(x, cond, padding)
        shift, scale = self.final_modulation(F.silu(cond)).unsqueeze(0).chunk(2, dim=2)
        x = self.final_norm(x[ts + 1:]) * (1 + scale) + shift
        return self.out(x), similarity


def grouped_mse(prediction, target, padding):
    keep = (~padding).t().unsqueeze(2).float()
    frames = keep.sum(0).squeeze(1).clamp_min(1.0)
    squared = (prediction - target) ** 2 * keep
    groups = [squared[:, :, b:e].sum((0, 2)) / (frames * (e - b)) for b, e in GROUPS]
    return torch.stack(groups, 0).mean(0).mean()


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--batch-dir", required=True)
    p.add_argument("--dim", type=int, default=128)
    p.add_argument("--cond-layers", type=int, default=2)
    p.add_argument("--layers", type=int, default=4)
    p.add_argument("--heads", type=int, default=4)
    p.add_argument("--ff", type=int, default=256)
    p.add_argument("--vocab", type=int, default=1000)
    p.add_argument("--dropout", type=float, default=0.1)
    p.add_argument("--steps", type=int, default=5)
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--threads", type=int, default=1)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(1)
    load = lambda name: torch.from_numpy(np.load(os.path.join(a.batch_dir, name + ".npy")))
    tokens, source, target = load("tokens"), load("source"), load("target")
    source_padding, target_padding, classes = load("source_padding"), load("target_padding"), load("classes")
    n = target.shape[1]
    f = lambda t: math.cos((t / 300 + 0.008) / 1.008 * math.pi / 2) ** 2
    abar = torch.tensor([f(t + 1) / f(0) for t in range(300)], dtype=torch.float32)
    model = Mdt(a)
    model.train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=0.01)
    class_weights = torch.tensor([1.0, 0.0, 1.0])

    def step():
        t = torch.randint(0, 300, (n,))
        u = torch.rand(n)
        drop_text = u < 0.2
        drop_source = (u < 0.15) | ((u >= 0.2) & (u < 0.25))
        noise = torch.randn_like(target)
        xt = abar[t].sqrt().view(1, -1, 1) * target + (1 - abar[t]).sqrt().view(1, -1, 1) * noise
        x0, similarity = model(xt, t, target_padding, tokens, source, source_padding, drop_text, drop_source)
        loss = grouped_mse(x0, target, target_padding)
        valid = (classes >= 0) & ~source_padding & ~drop_source.view(-1, 1)
        labels = classes.clamp_min(0)
        nll = -torch.log_softmax(similarity, 2).gather(2, labels.unsqueeze(2)).squeeze(2)
        w = class_weights[labels] * valid.float()
        loss = loss + 0.05 * (nll * w).sum() / w.sum().clamp_min(1e-8)
        optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        optimizer.step()
        return loss.item()

    report_timed_steps(step, a.warmup, a.steps, n)


if __name__ == "__main__":
    main()
