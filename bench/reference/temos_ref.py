#!/usr/bin/python3
"""TEMOS (REFERENCE 4.5) in PyTorch Python: the same architecture as plugins/temos_sinc (learned
text encoder, text and motion VAE encoders with mu/logvar tokens, a transformer decoder over
positional queries; smooth-L1 reconstructions of both branches, four KL terms and the latent loss),
trained on the batch bench/train_bench writes, with AdamW and gradient clipping, timed.

  /usr/bin/python3 bench/reference/temos_ref.py --batch-dir DIR --latent 128 --layers 2 --heads 4 \
      --ff 512 --text-layers 1 --vocab 1000 --steps 10 --threads 1
prints one JSON line: {"samples_per_second": ..., "seconds": ..., "loss": ...}
"""
import argparse
import json
import math
import os
import time

import numpy as np
import torch
from torch import nn
import torch.nn.functional as F


def positional_encoding(length, dim):
    position = torch.arange(length, dtype=torch.float32).unsqueeze(1)
    div = torch.exp(torch.arange(0, dim, 2, dtype=torch.float32) * (-math.log(10000.0) / dim))
    pe = torch.zeros(length, dim)
    pe[:, 0::2] = torch.sin(position * div)
    pe[:, 1::2] = torch.cos(position * div)
    return pe.unsqueeze(1)


def encoder(dim, heads, ff, dropout, layers):
    layer = nn.TransformerEncoderLayer(dim, heads, ff, dropout, activation="gelu")
    return nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)


class TextEncoder(nn.Module):
    def __init__(self, vocab, dim, heads, ff, dropout, layers):
        super().__init__()
        self.dim = dim
        self.embed = nn.Embedding(vocab + 2, dim, padding_idx=0)
        # As plugins/common/text_encoder.cc: entries N(0, 1/dim), times sqrt(dim) in forward().
        with torch.no_grad():
            self.embed.weight.normal_(0.0, 1.0 / math.sqrt(dim))
            self.embed.weight[0].zero_()
        self.encoder = encoder(dim, heads, ff, dropout, layers)

    def forward(self, tokens):
        padding = tokens.eq(0)
        x = self.embed(tokens).transpose(0, 1) * math.sqrt(self.dim)
        x = x + positional_encoding(tokens.shape[1], self.dim)
        return self.encoder(x, src_key_padding_mask=padding), padding


class VaeEncoder(nn.Module):
    def __init__(self, input_dim, latent, heads, ff, dropout, layers):
        super().__init__()
        self.latent = latent
        self.project = nn.Linear(input_dim, latent)
        self.mu_token = nn.Parameter(torch.randn(latent) * 0.02)
        self.logvar_token = nn.Parameter(torch.randn(latent) * 0.02)
        self.encoder = encoder(latent, heads, ff, dropout, layers)

    def forward(self, x, padding):
        length, n = x.shape[0], x.shape[1]
        h = self.project(x)
        tokens = torch.stack([self.mu_token, self.logvar_token]).unsqueeze(1).expand(2, n, self.latent)
        h = torch.cat([tokens, h], 0) + positional_encoding(length + 2, self.latent)
        mask = torch.cat([torch.zeros(n, 2, dtype=torch.bool), padding], 1)
        out = self.encoder(h, src_key_padding_mask=mask)
        return out[0], out[1]


class Decoder(nn.Module):
    def __init__(self, latent, heads, ff, dropout, layers, feature_dim=135):
        super().__init__()
        self.latent = latent
        layer = nn.TransformerDecoderLayer(latent, heads, ff, dropout, activation="gelu")
        self.decoder = nn.TransformerDecoder(layer, layers)
        self.out = nn.Linear(latent, feature_dim)

    def forward(self, z, padding):
        n, length = z.shape[0], padding.shape[1]
        queries = positional_encoding(length, self.latent).expand(length, n, self.latent)
        h = self.decoder(queries, z.unsqueeze(0), tgt_key_padding_mask=padding)
        return self.out(h).masked_fill(padding.transpose(0, 1).unsqueeze(2), 0.0)


def masked_smooth_l1(prediction, target, padding):
    keep = (~padding).transpose(0, 1).unsqueeze(2).to(prediction.dtype)
    loss = F.smooth_l1_loss(prediction, target, reduction="none") * keep
    return (loss.sum((0, 2)) / (keep.sum((0, 2)) * prediction.shape[2]).clamp_min(1.0)).mean()


def kl(mu_q, logvar_q, mu_p, logvar_p):
    # The mean over every element, as TEMOS's kl_divergence(q, p).mean() and plugins/temos_sinc.
    return (0.5 * (logvar_p - logvar_q + (logvar_q.exp() + (mu_q - mu_p) ** 2) / logvar_p.exp() - 1.0)).mean()


class Temos(nn.Module):
    def __init__(self, a):
        super().__init__()
        self.text_encoder = TextEncoder(a.vocab, a.latent, a.heads, a.ff, a.dropout, a.text_layers)
        self.text_vae = VaeEncoder(a.latent, a.latent, a.heads, a.ff, a.dropout, a.layers)
        self.motion_vae = VaeEncoder(135, a.latent, a.heads, a.ff, a.dropout, a.layers)
        self.decoder = Decoder(a.latent, a.heads, a.ff, a.dropout, a.layers)

    def encode_text(self, tokens):
        text, text_padding = self.text_encoder(tokens)
        return self.text_vae(text, text_padding)

    def losses(self, tokens, features, padding, eps=None):
        """TEMOS's loss; with `eps` [2, N, latent] the reparameterisation noise of the text and
        motion latents is given (else drawn). Returns the loss and the two encoders' means."""
        t_mu, t_logvar = self.encode_text(tokens)
        m_mu, m_logvar = self.motion_vae(features, padding)
        if eps is None:
            eps = torch.randn(2, *t_mu.shape)
        t_z = t_mu + torch.exp(0.5 * t_logvar) * eps[0]
        m_z = m_mu + torch.exp(0.5 * m_logvar) * eps[1]
        n = features.shape[1]
        decoded = self.decoder(torch.cat([t_z, m_z]), padding.repeat(2, 1))
        zeros = torch.zeros_like(m_mu)
        loss = masked_smooth_l1(decoded[:, :n], features, padding) + masked_smooth_l1(decoded[:, n:], features, padding)
        loss = loss + 1e-5 * (kl(t_mu, t_logvar, m_mu, m_logvar) + kl(m_mu, m_logvar, t_mu, t_logvar) +
                              kl(t_mu, t_logvar, zeros, zeros) + kl(m_mu, m_logvar, zeros, zeros))
        return loss + 1e-5 * F.smooth_l1_loss(t_z, m_z), t_mu, m_mu


def report_timed_steps(step, warmup, steps, batch):
    """Runs `warmup` untimed steps, then times `steps`; prints the JSON line the benchmarks parse."""
    for _ in range(warmup):
        step()
    start = time.perf_counter()
    loss = 0.0
    for _ in range(steps):
        loss = step()
    seconds = time.perf_counter() - start
    print(json.dumps({"samples_per_second": steps * batch / seconds, "seconds": seconds, "loss": loss}))


def add_model_arguments(p, vocab):
    """The model's sizes, as the C++ side passes them."""
    p.add_argument("--latent", type=int, default=128)
    p.add_argument("--layers", type=int, default=2)
    p.add_argument("--heads", type=int, default=4)
    p.add_argument("--ff", type=int, default=512)
    p.add_argument("--text-layers", type=int, default=1)
    p.add_argument("--vocab", type=int, default=vocab)
    p.add_argument("--dropout", type=float, default=0.1)
    p.add_argument("--threads", type=int, default=1)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--batch-dir", required=True)
    add_model_arguments(p, vocab=1000)
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--warmup", type=int, default=2)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(1)
    tokens = torch.from_numpy(np.load(os.path.join(a.batch_dir, "tokens.npy")))
    features = torch.from_numpy(np.load(os.path.join(a.batch_dir, "features.npy")))
    padding = torch.from_numpy(np.load(os.path.join(a.batch_dir, "padding.npy")))
    model = Temos(a)
    model.train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=0.01)

    def step():
        loss, _, _ = model.losses(tokens, features, padding)
        optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        optimizer.step()
        return loss.item()

    report_timed_steps(step, a.warmup, a.steps, features.shape[1])


if __name__ == "__main__":
    main()
