#!/usr/bin/python3
"""A learned clean-up of the legs (issue 15, the measurement of the lever that plugins/leg_cleanup now runs).

The demo's edits skate on 0.55 of contact frames (targets 0.006) because the network's leg rotations
and pelvis path do not agree to within the 0.2 degrees per 10-fps frame that the skate measure asks
(docs/EXPERIMENTS.md); a foot-level clean-up (foot_lock) halves it. This trains a small temporal
network on the corpus's own training motions (the train split of a motionfix triplet directory, both
sides of each triplet) to give back a motion's clean hip, knee and ankle rotations from corrupted
ones, given the pelvis as it is (Holden 2018, "Robust solving of optical motion capture data by
denoising", applied to the legs of generated motion). The corruptions imitate what the edits' legs
carry: noise at the network's 10-fps frames interpolated to 30 fps, a slow random offset, the legs
drawn part of the way toward the triplet partner's (an edit keeps 17% of the way back to its source),
and the legs' timing warped against the pelvis; with --shrink, a share of the batch with the legs'
swing narrowed (legs that do not step, as SINC's), and with --height the pelvis height drifted, the
network then also giving back a height correction (the edits float on a fifth of their frames).
The loss: the rotations (matrix entries), the leg joints' world positions by forward kinematics,
and the speed of foot joints where the clean motion stands on them (contact: below 5 cm and slower
than 0.15 m/s, the evaluation's figures).

    /usr/bin/python3 tools/leg_denoise.py train out/demo-1/corpus/result/motionfix out/denoise/model.pt \
        --shrink 0.25 --height
    /usr/bin/python3 tools/leg_denoise.py apply out/denoise/model.pt out/demo-1/edit_mdt out/denoise/edit_mdt

`apply` writes each input task's edited.npz (or generated.npz) with the legs replaced, every other
array as it was, so eval_edit / eval_generate score it as a row of its own (an experiment config
names the directory); the pelvis's path and orientation and the upper body stay the model's (its
height too, without --height). A measurement: the corpus's prior, it makes real mocap slide more
(docs/EXPERIMENTS.md "A learned clean-up of the legs"). The pipeline's own: the leg_cleanup model
plugin (the same net in LibTorch, trained by the train stage) and the clean_legs stage kind
(configs/experiments/issue15_clean_legs.yaml; the demo's row).
"""
import argparse
import glob
import math
import os
import shutil
import sys
import time

import numpy as np
import torch
import torch.nn as nn

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from root_stats import CONTACT_HEIGHT, SKATE_SPEED, leg_offsets, log_rotation, stage_files  # noqa: E402
from root_stats import LEGS as CHAINS  # noqa: E402  (hip, knee, ankle, foot per leg)

LEG = (1, 2, 4, 5, 7, 8)  # hips, knees, ankles (SMPL-22): the joints whose rotations move the feet
CROP = 60  # training crop, frames at 30 fps (the edits are 2-4 s)


def rodrigues(v):
    """Rotation matrices [..., 3, 3] of rotation vectors [..., 3] (torch)."""
    angle = v.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    k = v / angle
    zero = torch.zeros_like(k[..., 0])
    K = torch.stack([zero, -k[..., 2], k[..., 1], k[..., 2], zero, -k[..., 0], -k[..., 1], k[..., 0], zero],
                    dim=-1).reshape(v.shape[:-1] + (3, 3))
    s, c = torch.sin(angle)[..., None], torch.cos(angle)[..., None]
    eye = torch.eye(3, dtype=v.dtype).expand(K.shape)
    return eye + s * K + (1 - c) * (K @ K)


def log_map(R):
    """Rotation vectors of rotation matrices (torch; angles below pi)."""
    cos = ((R.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1 + 1e-6, 1 - 1e-6)
    angle = torch.acos(cos)
    axis = torch.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    return axis * (angle / (2 * torch.sin(angle).clamp_min(1e-6)))[..., None]


def six_d(R):
    """The first two columns [..., 6] (Zhou et al. 2019)."""
    return torch.cat([R[..., :, 0], R[..., :, 1]], dim=-1)


def from_six_d(x):
    a, b = x[..., :3], x[..., 3:]
    e1 = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    b = b - (e1 * b).sum(-1, keepdim=True) * e1
    e2 = b / b.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    return torch.stack([e1, e2, torch.cross(e1, e2, dim=-1)], dim=-1)


def heading(R0):
    """The yaw (radians) of the body's forward axis (its y-up rest frame's z) in the z-up world."""
    forward = R0[..., :, 2]
    return torch.atan2(forward[..., 1], forward[..., 0])


def yaw_matrix(angle):
    c, s = torch.cos(angle), torch.sin(angle)
    zero, one = torch.zeros_like(c), torch.ones_like(c)
    return torch.stack([c, -s, zero, s, c, zero, zero, zero, one], -1).reshape(angle.shape + (3, 3))


def root_features(trans, R0, fps):
    """Per frame [B, T, 11], heading-free: the pelvis height, its velocity in the heading frame (m/s),
    the heading's angular speed (rad/s) and the pelvis orientation without heading (6D)."""
    h = heading(R0)
    unturn = yaw_matrix(-h)
    velocity = torch.diff(trans, dim=1, append=trans[:, -1:] * 2 - trans[:, -2:-1]) * fps
    velocity = (unturn @ velocity[..., None])[..., 0]
    turn = torch.diff(h, dim=1, append=h[:, -1:])
    turn = (turn + math.pi) % (2 * math.pi) - math.pi
    return torch.cat([trans[..., 2:3], velocity, turn[..., None] * fps, six_d(unturn @ R0)], dim=-1)


class Denoiser(nn.Module):
    """Temporal convolutions (replicate padding, dilations 1-8: a receptive field of about 2 s) from
    the root features and the noisy legs to a correction of the legs' 6D rotations."""

    def __init__(self, width=256, blocks=(1, 2, 4, 8, 1), height=False):
        super().__init__()
        self.height = height
        channels = 11 + 6 * len(LEG)
        self.inp = nn.Conv1d(channels, width, 5, padding=2, padding_mode="replicate")
        self.blocks = nn.ModuleList(nn.Conv1d(width, width, 5, padding=2 * d, dilation=d, padding_mode="replicate")
                                    for d in blocks)
        self.out = nn.Conv1d(width, 6 * len(LEG) + int(height), 1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, root, legs):
        """root [B, T, 11], legs [B, T, 6, 3, 3] -> legs [B, T, 6, 3, 3] and the pelvis height's
        correction [B, T] (metres; zeros unless the model was trained with --height)."""
        legs6 = six_d(legs).flatten(2)
        h = self.inp(torch.cat([root, legs6], -1).transpose(1, 2))
        for block in self.blocks:
            h = h + block(nn.functional.gelu(h))
        delta = self.out(nn.functional.gelu(h)).transpose(1, 2)
        dz = delta[..., -1] if self.height else torch.zeros(delta.shape[:2])
        legs6 = legs6 + delta[..., :legs6.shape[-1]]
        return from_six_d(legs6.reshape(legs.shape[:3] + (6,))), dz


def leg_positions(trans, R0, legs, offsets):
    """World positions [B, T, 8, 3] of the knees, ankles and foot joints (forward kinematics)."""
    rotation = {0: R0}
    for k, joint in enumerate(LEG):
        rotation[joint] = legs[:, :, k]
    out = []
    for chain in CHAINS:
        world = R0
        position = trans + (R0 @ offsets[chain[0]])
        for k in range(1, len(chain)):
            world = world @ rotation[chain[k - 1]]
            position = position + (world @ offsets[chain[k]])
            out.append(position)
    return torch.stack(out, dim=2)


def load_triplets(directory, split, limit):
    """[(trans [T, 3], R0 [T, 3, 3], legs [T, 6, 3, 3], partner index)] for both sides of the split's
    triplets (the partner: the other side), up to limit triplets."""
    files = sorted(glob.glob(os.path.join(directory, "*.npz")))
    if not files:
        sys.exit(f"{directory}: no triplet npz files (a corpus stage's result/motionfix directory)")
    motions = []
    for path in files:
        with np.load(path) as z:
            if "target_poses" not in z.files:
                sys.exit(f"{path}: not a triplet file (no target_poses)")
            keep = np.flatnonzero(z["splits"] == split)
            arrays = {k: z[k] for k in ("source_offsets", "source_poses", "source_trans", "target_offsets",
                                        "target_poses", "target_trans", "fps")}
        for i in keep:
            if arrays["fps"][i] != 30:
                sys.exit(f"{path}: triplet {i} at {arrays['fps'][i]:g} fps (the clean-up is trained at 30)")
            pair = []
            for side in ("source", "target"):
                a, b = arrays[side + "_offsets"][i], arrays[side + "_offsets"][i + 1]
                poses = torch.from_numpy(arrays[side + "_poses"][a:b].astype(np.float32))
                R = rodrigues(poses)
                pair.append((torch.from_numpy(arrays[side + "_trans"][a:b].astype(np.float32)), R[:, 0],
                             R[:, list(LEG)].contiguous()))
            n = len(motions)
            motions += [pair[0] + (n + 1,), pair[1] + (n,)]
            if len(motions) >= 2 * limit:
                return motions
    return motions


def smooth_noise(shape, sigma_frames, generator):
    """Gaussian noise [B, T, J, 3] filtered along time (sigma in frames), rescaled to unit spread."""
    x = torch.randn(shape, generator=generator)
    radius = int(3 * sigma_frames) + 1
    kernel = torch.exp(-0.5 * (torch.arange(-radius, radius + 1, dtype=torch.float32) / sigma_frames) ** 2)
    kernel = (kernel / kernel.sum()).reshape(1, 1, -1)
    B, T, J, C = shape
    flat = x.permute(0, 2, 3, 1).reshape(-1, 1, T)
    flat = nn.functional.conv1d(nn.functional.pad(flat, (radius, radius), mode="replicate"), kernel)
    flat = flat / flat.std().clamp_min(1e-8)
    return flat.reshape(B, J, C, T).permute(0, 3, 1, 2)


def corrupt(legs, partner, generator, degrees, shrink=0.0):
    """legs [B, T, 6, 3, 3] corrupted as the edits' are (module docstring); partner: the partner
    motions' legs on the same frames."""
    B, T = legs.shape[:2]
    u = lambda: torch.rand(B, 1, 1, 1, generator=generator)  # noqa: E731
    # 10-fps key noise interpolated to 30 fps, of spread up to `degrees`.
    keys = torch.randn(B, (T + 2) // 3 + 1, len(LEG), 3, generator=generator)
    key_noise = nn.functional.interpolate(keys.permute(0, 2, 3, 1).reshape(B, -1, keys.shape[1]),
                                          size=3 * (keys.shape[1] - 1) + 1, mode="linear", align_corners=True)
    key_noise = key_noise[..., :T].reshape(B, len(LEG), 3, T).permute(0, 3, 1, 2)
    e = math.radians(degrees) * u() * key_noise
    # a slow offset, up to 3x that, over 0.1-0.5 s
    amplitude = 3 * math.radians(degrees) * u()  # drawn before the time scale (the runs' order)
    sigma = 3 + 12 * float(torch.rand(1, generator=generator))
    e = e + amplitude * smooth_noise((B, T, len(LEG), 3), sigma, generator)
    # part of the way toward the partner's legs, for half the batch
    toward = (torch.rand(B, 1, 1, generator=generator) < 0.5) * 0.4 * torch.rand(B, 1, 1, generator=generator)
    e = e + toward[..., None] * log_map(legs.transpose(-1, -2) @ partner)
    noisy = legs @ rodrigues(e)
    # the legs' timing warped against the pelvis (a third of the batch): rate 0.85-1.15
    warp = torch.rand(B, generator=generator) < 0.3
    if warp.any():
        rate = 0.85 + 0.3 * torch.rand(int(warp.sum()), generator=generator)
        t = torch.arange(T, dtype=torch.float32)
        centre = (T - 1) / 2
        src = ((t[None] - centre) * rate[:, None] + centre).clamp(0, T - 1)
        lo = src.floor().long()
        hi = (lo + 1).clamp(max=T - 1)
        w = (src - lo)[..., None, None]
        sel = noisy[warp]
        six = six_d(sel)
        gather = lambda idx: torch.gather(six, 1, idx[:, :, None, None].expand(-1, -1, len(LEG), 6))  # noqa: E731
        noisy = noisy.clone()
        noisy[warp] = from_six_d(gather(lo) * (1 - w) + gather(hi) * w)
    # the legs' swing shrunk toward their mean over the window (a share `shrink` of the batch, to
    # 0.2-1 of its range): legs that do not step while the pelvis travels, as SINC's generations
    pick = torch.rand(B, generator=generator) < shrink if shrink > 0 else torch.zeros(B, dtype=torch.bool)
    if pick.any():
        six = six_d(noisy[pick])
        scale = (0.2 + 0.8 * torch.rand(int(pick.sum()), generator=generator))[:, None, None, None]
        mean = six.mean(dim=1, keepdim=True)
        noisy = noisy.clone()
        noisy[pick] = from_six_d(mean + scale * (six - mean))
    return noisy


def batch(motions, indices, generator):
    """Random CROP-frame windows of the motions (and the partner's legs on the same frames)."""
    trans, R0, legs, partner = [], [], [], []
    for i in indices:
        t, r, l, p = motions[i]
        start = int(torch.randint(0, len(t) - CROP + 1, (1,), generator=generator))
        pl = motions[p][2]
        idx = torch.arange(start, start + CROP).clamp(max=len(pl) - 1)
        trans.append(t[start:start + CROP])
        R0.append(r[start:start + CROP])
        legs.append(l[start:start + CROP])
        partner.append(pl[idx])
    return torch.stack(trans), torch.stack(R0), torch.stack(legs), torch.stack(partner)


def height_drift(shape, generator):
    """A pelvis height error [B, T] (metres): an offset of up to 5 cm, a drift of up to 15 cm over
    the window and a slow wobble of up to 5 cm (the edits drift 17 cm over at most 4 s and sink 3 cm
    on average; docs/EXPERIMENTS.md)."""
    B, T = shape
    u = lambda: 2 * torch.rand(B, 1, generator=generator) - 1  # noqa: E731
    ramp = torch.linspace(-0.5, 0.5, T)[None]
    wobble = smooth_noise((B, T, 1, 1), 10 + 20 * float(torch.rand(1, generator=generator)), generator)[..., 0, 0]
    return 0.05 * u() + 0.15 * u() * ramp + 0.05 * u().abs() * wobble


def losses(model, trans, R0, legs, partner, offsets, generator, degrees, shrink=0.0, fps=30.0):
    noisy = corrupt(legs, partner, generator, degrees, shrink)
    given = trans
    if model.height:  # the pelvis height drifted, as the edits' (integrated from a velocity) does
        given = trans.clone()
        given[..., 2] += height_drift(trans.shape[:2], generator)
    out, dz = model(root_features(given, R0, fps), noisy)
    rot = ((out - legs) ** 2).mean()
    corrected = given.clone()
    corrected[..., 2] += dz
    p_out, p_ref = leg_positions(corrected, R0, out, offsets), leg_positions(trans, R0, legs, offsets)
    pos = ((p_out - p_ref) ** 2).sum(-1).mean()
    speed_ref = torch.diff(p_ref[..., :2], dim=1).norm(dim=-1) * fps
    contact = (p_ref[:, 1:, :, 2] < CONTACT_HEIGHT) & (p_ref[:, :-1, :, 2] < CONTACT_HEIGHT) & (speed_ref < SKATE_SPEED)
    joint_is_foot = torch.tensor([False, True, True, False, True, True])  # knee, ankle, foot per leg
    contact = contact & joint_is_foot
    v_out = (torch.diff(p_out[..., :2], dim=1) * fps) ** 2
    slide = (v_out.sum(-1) * contact).sum() / contact.sum().clamp_min(1)
    return rot, pos, slide


def train(args):
    torch.set_num_threads(args.threads)
    generator = torch.Generator().manual_seed(args.seed)
    torch.manual_seed(args.seed)
    offsets = {j: torch.tensor(v, dtype=torch.float32) for j, v in leg_offsets().items()}
    t0 = time.time()
    motions = load_triplets(args.triplets, "train", args.limit)
    motions_val = load_triplets(args.triplets, "val", 256)
    usable = [i for i, m in enumerate(motions) if len(m[0]) >= CROP]
    usable_val = [i for i, m in enumerate(motions_val) if len(m[0]) >= CROP]
    if not usable or not usable_val:
        sys.exit(f"{args.triplets}: no {'train' if not usable else 'val'}-split triplets of {CROP} frames or more")
    print(f"{len(motions)} training motions ({len(usable)} of {CROP}+ frames), {len(motions_val)} validation; "
          f"loaded in {time.time() - t0:.0f} s", flush=True)
    model = Denoiser(args.width, height=args.height)
    optimiser = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, max_lr=args.lr, total_steps=args.steps,
                                                   pct_start=max(0.05, 2.0 / args.steps))
    weights = (1.0, 10.0, args.slide)
    val_generator = torch.Generator().manual_seed(12345)
    val_batch = batch(motions_val, usable_val[:256], val_generator)
    best = float("inf")
    t0 = time.time()
    for step in range(1, args.steps + 1):
        pick = torch.randint(0, len(usable), (args.batch,), generator=generator)
        terms = losses(model, *batch(motions, [usable[i] for i in pick], generator), offsets, generator,
                       args.degrees, args.shrink)
        loss = sum(w * x for w, x in zip(weights, terms))
        optimiser.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        optimiser.step()
        schedule.step()
        if step % args.log == 0 or step == args.steps:
            with torch.no_grad():
                vg = torch.Generator().manual_seed(777)
                val_terms = losses(model, *val_batch, offsets, vg, args.degrees, args.shrink)
                val = sum(w * x for w, x in zip(weights, val_terms)).item()
            print(f"step {step} loss {loss.item():.5f} (rot {terms[0].item():.5f} pos {terms[1].item():.6f} "
                  f"slide {terms[2].item():.4f}) val {val:.5f} (slide {val_terms[2].item():.4f}) "
                  f"{time.time() - t0:.0f} s", flush=True)
            if val < best:
                best = val
                os.makedirs(os.path.dirname(os.path.abspath(args.model)), exist_ok=True)
                tmp = args.model + ".tmp"
                torch.save({"width": args.width, "height": args.height, "state": model.state_dict(), "step": step,
                            "val": val}, tmp)
                os.replace(tmp, args.model)


def apply(args):
    torch.set_num_threads(args.threads)
    saved = torch.load(args.model)
    model = Denoiser(saved["width"], height=saved.get("height", False))
    model.load_state_dict(saved["state"])
    model.eval()
    files = stage_files(args.motions)
    for path in files:
        task = os.path.basename(os.path.dirname(path))
        out_dir = os.path.join(args.out, task)
        os.makedirs(out_dir, exist_ok=True)
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        poses, trans, offsets, fps = arrays["poses"].copy(), arrays["trans"].copy(), arrays["offsets"], arrays["fps"]
        for i in range(len(offsets) - 1):
            a, b = offsets[i], offsets[i + 1]
            if b - a < 8:
                continue
            if fps[i] != 30:
                sys.exit(f"{path}: motion {i} at {fps[i]:g} fps (the clean-up is trained at 30)")
            R = rodrigues(torch.from_numpy(poses[a:b].astype(np.float32)))
            t = torch.from_numpy(trans[a:b].astype(np.float32))
            with torch.no_grad():
                legs, dz = model(root_features(t[None], R[None, :, 0], 30.0), R[None, :, list(LEG)])
            poses[a:b][:, list(LEG)] = log_rotation(legs[0].double().numpy()).astype(poses.dtype)
            trans[a:b, 2] += dz[0].numpy().astype(trans.dtype)
        arrays["poses"], arrays["trans"] = poses, trans
        name = os.path.basename(path)
        tmp = os.path.join(out_dir, name + ".tmp.npz")
        np.savez(tmp, **arrays)
        os.replace(tmp, os.path.join(out_dir, name))
        for side in glob.glob(os.path.join(os.path.dirname(path), "*.json")):
            shutil.copy(side, out_dir)
    print(f"{args.out}: {len(files)} task(s) written")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="train on a triplet directory's train split")
    t.add_argument("triplets", help="a corpus stage's result/motionfix directory")
    t.add_argument("model", help="where the best model (by a validation batch) is written")
    t.add_argument("--steps", type=int, default=2500)
    t.add_argument("--batch", type=int, default=64)
    t.add_argument("--lr", type=float, default=1e-3)
    t.add_argument("--width", type=int, default=256)
    t.add_argument("--degrees", type=float, default=1.0, help="spread of the 10-fps key noise (the slow offset: 3x)")
    t.add_argument("--shrink", type=float, default=0.0,
                   help="share of the batch whose legs' swing is shrunk (legs that do not step)")
    t.add_argument("--height", action="store_true",
                   help="also correct the pelvis height (trained on heights drifted as the edits' are)")
    t.add_argument("--slide", type=float, default=0.1, help="weight of the contact feet's squared speed")
    t.add_argument("--limit", type=int, default=8000, help="training triplets used")
    t.add_argument("--log", type=int, default=250, help="steps between validations (the best is kept)")
    t.add_argument("--seed", type=int, default=1)
    t.add_argument("--threads", type=int, default=2)
    a = sub.add_parser("apply", help="clean the legs of an edit/generate/foot_lock stage's motions")
    a.add_argument("model")
    a.add_argument("motions", help="the stage's output directory (out/JOB/STAGE)")
    a.add_argument("out", help="a directory to write task-*/edited.npz (or generated.npz) into")
    a.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    train(args) if args.command == "train" else apply(args)


if __name__ == "__main__":
    main()
