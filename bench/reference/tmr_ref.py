#!/usr/bin/python3
"""TMR (REFERENCE 5) in PyTorch Python: temos_ref.py's TEMOS with the contrastive term (symmetric
InfoNCE on the cosine of the two encoders' means, temperature 0.1, weight 0.1, near-duplicate texts
removed from the negatives), trained the way bench/tmr_quality.cc trains plugins/temos_sinc's, on
the stream it writes into --dir: its initial weights (init/*.npy, C++ names), every step's batch
(features, padding, token ids, near-duplicate mask, reparameterisation noise) and learning rate.
AdamW (betas 0.9/0.999, weight decay 0.01) after clipping the gradients' norm to 1, as the train
stage. Before training and every --every steps the test singles' text and motion means go to
python_<step>_text.npy / python_<step>_motion.npy for the C++ side to score; the training seconds
exclude those encodings. --bf16: each step's forward pass under CPU bf16 autocast (the C++ side's
--quality-precision bf16); the test means are encoded in float32 either way.

  /usr/bin/python3 bench/reference/tmr_ref.py --dir DIR --steps 400 --every 50 --threads 1
prints one JSON line: {"first_eval_loss": ..., "checkpoints": [{"step": ..., "seconds": ...}], ...}
"""
import argparse
import json
import os
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from temos_ref import Temos, add_model_arguments  # noqa: E402


def info_nce(a, b, temperature, duplicate):
    logits = F.normalize(a, dim=1) @ F.normalize(b, dim=1).t() / temperature
    logits = logits.masked_fill(duplicate, -1e9)  # near-duplicates are not negatives
    target = torch.arange(a.shape[0])
    return 0.5 * (F.cross_entropy(logits, target) + F.cross_entropy(logits.t(), target))


class Tmr(Temos):
    def tmr_loss(self, tokens, features, padding, eps, duplicate):
        loss, t_mu, m_mu = self.losses(tokens, features, padding, eps)
        return loss + 0.1 * info_nce(t_mu, m_mu, 0.1, duplicate)


def load_cpp_weights(model, init_dir):
    """Copies the C++ model's initial parameters (one .npy per parameter, its C++ name) into the
    reference. The decoder's cross-attention to its one memory token: C++ keeps only the value and
    output projections (softmax over one key is 1), which are the value rows of
    MultiheadAttention's in_proj and its out_proj here; the query/key rows cannot matter."""
    state = model.state_dict()
    dim = model.decoder.latent
    loaded = set()
    for file in sorted(os.listdir(init_dir)):
        name = file[:-len(".npy")]
        if name == "text_encoder.separator":  # SINC-STE's, unused by TMR
            continue
        target, rows = name, None
        target = target.replace(".self_attn.in_proj.weight", ".self_attn.in_proj_weight")
        target = target.replace(".self_attn.in_proj.bias", ".self_attn.in_proj_bias")
        if ".cross_value." in target:
            target = target.replace(".cross_value.weight", ".multihead_attn.in_proj_weight")
            target = target.replace(".cross_value.bias", ".multihead_attn.in_proj_bias")
            rows = slice(2 * dim, 3 * dim)
        target = target.replace(".cross_out_proj.", ".multihead_attn.out_proj.")
        if target not in state:
            sys.exit(f"{os.path.join(init_dir, file)}: the reference has no parameter {target}")
        value = torch.from_numpy(np.load(os.path.join(init_dir, file)))
        dest = state[target] if rows is None else state[target][rows]
        if dest.shape != value.shape:
            sys.exit(f"{os.path.join(init_dir, file)}: shape {tuple(value.shape)}, the reference's {target} "
                     f"is {tuple(dest.shape)}")
        with torch.no_grad():
            dest.copy_(value)
        loaded.add(target)
    missing = [k for k in state if k not in loaded and not k.endswith(("multihead_attn.in_proj_weight",
                                                                         "multihead_attn.in_proj_bias"))]
    if missing:
        sys.exit(f"{init_dir}: no initial value for {', '.join(missing)}")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--dir", required=True)
    add_model_arguments(p, vocab=800)
    p.add_argument("--steps", type=int, default=400)
    p.add_argument("--every", type=int, default=50)
    p.add_argument("--bf16", action="store_true", help="each forward pass under CPU bf16 autocast")
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(1)
    d = a.dir
    load = lambda name: np.load(os.path.join(d, name))  # noqa: E731
    features, padding, tokens = load("features.npy"), load("padding.npy"), load("tokens.npy")
    eps, duplicate, lrs = load("eps.npy"), load("duplicate.npy"), load("lr.npy")
    frames, token_length = load("frames.npy"), load("token_length.npy")
    if features.shape[0] < a.steps:
        sys.exit(f"{d}/features.npy: {features.shape[0]} steps written, {a.steps} asked")
    test_features = torch.from_numpy(load("test_features.npy"))
    test_padding = torch.from_numpy(load("test_padding.npy"))
    test_tokens = torch.from_numpy(load("test_tokens.npy"))

    model = Tmr(a)
    load_cpp_weights(model, os.path.join(d, "init"))
    optimizer = torch.optim.AdamW(model.parameters(), lr=float(lrs[0]), betas=(0.9, 0.999), weight_decay=0.01)

    def batch(step):
        t, k = int(frames[step]), int(token_length[step])
        return (torch.from_numpy(tokens[step, :, :k]), torch.from_numpy(features[step, :t]),
                torch.from_numpy(padding[step, :, :t]), torch.from_numpy(eps[step]),
                torch.from_numpy(duplicate[step]))

    def save_test_means(step):
        model.eval()
        with torch.no_grad():
            text_mu, _ = model.encode_text(test_tokens)
            motion_mu, _ = model.motion_vae(test_features, test_padding)
        model.train()
        prefix = os.path.join(d, f"python_{step}")
        np.save(prefix + "_text.npy", text_mu.numpy().astype(np.float32))
        np.save(prefix + "_motion.npy", motion_mu.numpy().astype(np.float32))

    model.eval()
    with torch.no_grad():
        first_eval_loss = model.tmr_loss(*batch(0)).item()
    save_test_means(0)  # the untrained yardstick
    model.train()
    seconds, first_loss, checkpoints = 0.0, None, [{"step": 0, "seconds": 0.0}]
    for step in range(a.steps):
        inputs = batch(step)
        started = time.perf_counter()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=a.bf16):
            loss = model.tmr_loss(*inputs)
        optimizer.zero_grad()
        loss.backward()
        for group in optimizer.param_groups:
            group["lr"] = float(lrs[step])
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        optimizer.step()
        seconds += time.perf_counter() - started
        if first_loss is None:
            first_loss = loss.item()
        if (step + 1) % a.every == 0 or step + 1 == a.steps:
            save_test_means(step + 1)
            checkpoints.append({"step": step + 1, "seconds": seconds})
    print(json.dumps({"first_eval_loss": first_eval_loss, "first_loss": first_loss, "checkpoints": checkpoints}))


if __name__ == "__main__":
    main()
