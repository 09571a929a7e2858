// What a relative motion feature forgets and its decoder needs back: where the motion starts.
#pragma once

#include "motionpipe/math/rotation.h"
#include "motionpipe/motion/motion.h"

namespace motionpipe {

struct MotionAnchor {
  double heading = 0;  // ZYX heading of the first frame's global orientation (radians)
  Vec3 translation;    // first frame's pelvis translation (metres, z-up)
};

// The anchor of `motion` (zero anchor for an empty motion).
MotionAnchor AnchorOf(const Motion& motion);

}  // namespace motionpipe
