// MDM's foot-contact loss (Tevet et al. 2023, sec. 3, L_foot) for the 207-d editing feature: the
// feet's velocities, found by forward kinematics of the predicted frame, are pushed to zero on the
// frames where the target's feet stand still. Not in SimMotionEdit's reference; an option of the
// editors (`loss: {foot_contact: w}`) for issue 15's plausibility (the edits' feet slide on about
// half of their contact frames, the targets' on under 1%).
//
// The kinematics read exactly the columns that decoding reads (REFERENCE.md section 2): the pelvis
// velocity 0:3, the heading-free orientation 3:9, the heading change 9:15 and the legs' local
// rotations in 15:141; the derived joint positions 141:207 are not used, so the loss acts on the
// motion an edit decodes to.
#pragma once

#include <torch/torch.h>

#include <cstdint>
#include <vector>

namespace motionpipe::mdt {

// The foot joints FootDisplacements moves and the contact head predicts, in this order.
inline constexpr int64_t kContactJoints = 4;

// The four foot joints (left ankle, left foot, right ankle, right foot: SMPL-22 joints 7, 10, 8,
// 11), displaced between frames i - 1 and i, in metres, in the heading frame of frame i - 1:
//   d_i = G_{i-1} v_i + H_i q_i - q_{i-1},
// with v the pelvis velocity (in the previous frame's pelvis frame), G the heading-free global
// orientation, H the heading change and q a foot's position relative to the pelvis, heading removed
// (the leg chain's forward kinematics on Skeleton::Smpl22's rest offsets).
// `features`: unnormalised 207-d frames [T, N, 207]; returns [T - 1, N, 4, 3] in float32 (the
// products are written out elementwise so that bf16 autocast leaves them in float32: a millimetre
// step is the difference of two positions near a metre).
torch::Tensor FootDisplacements(const torch::Tensor& features);

// L_foot: the mean squared speed (m/s)^2 of the prediction's foot joints over the (foot, frame
// pair)s where the target's foot moves slower than `contact_speed` m/s (the target's feet are in
// contact) and both frames are real. `prediction`, `target`: unnormalised [T, N, 207]; `padding`
// [N, T] (true = padded); `fps`: the frames' rate.
torch::Tensor FootContactLoss(const torch::Tensor& prediction, const torch::Tensor& target,
                              const torch::Tensor& padding, double fps, double contact_speed);

// MDM's velocity loss L_vel (Tevet et al. 2023, sec. 3) on the feet, through forward kinematics:
// the mean squared difference (m/s)^2 between the prediction's and the target's foot velocities
// (FootDisplacements times fps) over the four foot joints and every pair of real frames, contact
// or not. Where L_foot only asks standing feet to stop (and a prediction can meet it by lifting
// them), this asks the pelvis velocity and the leg rotations to move each foot as the target's
// moves: the coordination whose error makes the edits skate (issue 15: with the target's leg
// rotations and pelvis velocity put back, the demo MDT's one-step estimate stops skating).
torch::Tensor FootVelocityLoss(const torch::Tensor& prediction, const torch::Tensor& target,
                               const torch::Tensor& padding, double fps);

// Which foot joints a motion holds still, per frame: 1 where the joint's speed is below
// `still_speed` m/s, the speed being its displacements (FootDisplacements) to the previous and the
// next frame averaged (one-sided at the ends, as foot_lock's test), else 0. On the floor a still
// foot is a contact; the features carry no height, so a foot held still in the air counts too,
// which a lock that holds it still leaves as it is. `features`: unnormalised [T, N, 207] at `fps`;
// returns [T, N, 4] float32 (all 0 for a one-frame motion).
torch::Tensor ContactLabels(const torch::Tensor& features, double fps, double still_speed);

// The contact head's loss: binary cross-entropy of `logits` [T, N, 4] against `labels`
// (ContactLabels) averaged over the real frames (padding [N, T], true = padded) and the four
// joints.
torch::Tensor ContactLoss(const torch::Tensor& logits, const torch::Tensor& labels,
                          const torch::Tensor& padding);

// The contact head's probabilities `stands` [T, 4] for frames at `fps` (<= 0: at `rate` already),
// brought to `frames` frames at `rate` (linear in time, the last frame held past the end) and
// thresholded at 1/2: LockFeet's contacts ([frames * 4], 1 = stands).
std::vector<uint8_t> ContactsAtRate(const torch::Tensor& stands, double fps, double rate,
                                    int64_t frames);

}  // namespace motionpipe::mdt
