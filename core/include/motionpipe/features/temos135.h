// The 135-d per-frame feature of TEMOS / SINC (REFERENCE.md section 4.5, "globalvelandy" + rot6d):
//   0       pelvis height z
//   1:3     xy velocity of the pelvis trajectory (difference to the previous frame, 0 at frame 0)
//   3:135   the 22 joint rotations as 6D (joint 0 = global orientation)
// First-frame canonicalisation: the whole motion is turned about z so that the first frame's heading
// equals `canonical_heading`. The default -pi/2 is where the reference's "remove the heading, plus
// pi/2" lands: the shipped reference mean (data/stats) has the first pelvis facing -x.
#pragma once

#include "motionpipe/features/anchor.h"
#include "motionpipe/features/feature_matrix.h"
#include "motionpipe/motion/motion.h"

namespace motionpipe {

constexpr int kTemosFeatureDim = 135;
constexpr double kTemosCanonicalHeading = -kPi / 2;

FeatureMatrix EncodeTemos135(const Motion& motion, double canonical_heading = kTemosCanonicalHeading);

// Exact inverse given the original anchor (heading and xy of the first frame; z comes from the
// features). With a default anchor the motion starts at the origin facing `canonical_heading`.
Motion DecodeTemos135(const FeatureMatrix& features, const MotionAnchor& anchor, double fps,
                      double canonical_heading = kTemosCanonicalHeading);

// The anchor that makes DecodeTemos135 return the canonical motion itself.
MotionAnchor CanonicalTemosAnchor(double canonical_heading = kTemosCanonicalHeading);

}  // namespace motionpipe
