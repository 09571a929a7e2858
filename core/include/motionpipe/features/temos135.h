// The 135-d per-frame feature of TEMOS / SINC (REFERENCE.md section 4.5, "globalvelandy" + rot6d):
//   0       pelvis height z
//   1:3     xy velocity of the pelvis trajectory (difference to the previous frame, 0 at frame 0)
//   3:135   the 22 joint rotations as 6D (joint 0 = global orientation)
// First-frame canonicalisation: the whole motion is turned about z so that the first frame's
// heading equals `canonical_heading`. The default -pi/2 is where the reference's "remove the
// heading, plus pi/2" lands: the shipped reference mean (data/stats) has the first pelvis facing
// -x.
#pragma once

#include "motionpipe/features/anchor.h"
#include "motionpipe/features/feature_matrix.h"
#include "motionpipe/motion/motion.h"

namespace motionpipe {

constexpr int kTemosFeatureDim = 135;
constexpr double kTemosCanonicalHeading = -kPi / 2;

FeatureMatrix EncodeTemos135(const Motion& motion,
                             double canonical_heading = kTemosCanonicalHeading);

// The same features in float32 through the SIMD kernels: the synth stage's path (about 20x faster).
// poses [frames, 22, 3], trans [frames, 3]; writes out[frames * 135]. Agrees with EncodeTemos135 to
// about 1e-6.
void EncodeTemos135Fast(const float* poses, const float* trans, int64_t frames, float* out,
                        double canonical_heading = kTemosCanonicalHeading);

// The same, with every joint's rotations read from its own motion: joint j of frame f is at
// joint_poses[j][f * 66 + 3 j .. + 3] (so a body-part composition is featurised without building
// the composed motion first). `trans` [frames, 3] comes with the global orientation.
void EncodeTemos135FastJoints(const float* const* joint_poses, const float* trans, int64_t frames,
                              float* out, double canonical_heading = kTemosCanonicalHeading);

// The features of every k-th frame (frames 0, k, 2k, ...: the motion Resample'd by index to
// rate / k) from the features of every frame: those frames' heights and rotations, and each planar
// velocity the sum of the k it spans (the trajectory is turned once, by the first frame's heading,
// so the sum is the displacement). What the encoders give for the resampled motion; a model that
// runs at its own rate trains on these (issue 15). Writes (frames - 1) / k + 1 rows (0 for no
// frames) to `out`, which may be `features` itself, and returns that count. k >= 1.
int64_t EveryKthTemos135(const float* features, int64_t frames, int64_t k, float* out);

// Exact inverse given the original anchor (heading and xy of the first frame; z comes from the
// features). With a default anchor the motion starts at the origin facing `canonical_heading`.
Motion DecodeTemos135(const FeatureMatrix& features, const MotionAnchor& anchor, double fps,
                      double canonical_heading = kTemosCanonicalHeading);

// The anchor that makes DecodeTemos135 return the canonical motion itself.
MotionAnchor CanonicalTemosAnchor(double canonical_heading = kTemosCanonicalHeading);

}  // namespace motionpipe
