// Turns a clip script into an SMPL-22 motion. Physically sensible by construction:
//  - every pose comes from rotations + forward kinematics (bone lengths never change) and the
//    anatomical pose solver (knees and elbows are hinges);
//  - feet are planned as footsteps: a planted foot does not move (heel-strike and toe-off roll
//    about a fixed heel or toe), swings lift it over the floor, and the pelvis height is kept
//    within reach of every planted foot, so feet neither slide nor sink;
//  - consecutive base actions cross-fade, and stepping adjusts the feet between them;
//  - simultaneous actions are performed jointly: a gesturing arm stops swinging, the other arm
//    swings less, the torso compensates, and locomotion slows while the upper body is busy;
//  - secondary motion: arm swing, pelvis sway and rotation with torso counter-rotation, idle
//    weight shifts and breathing so that standing is never frozen.
#pragma once

#include <vector>

#include "motionpipe/corpus/script.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::corpus {

struct Synthesis {
  Motion motion;
  std::vector<Segment> segments;  // one per annotated action instance: frames, label, parts
  double max_reach_error = 0;     // metres an IK target was out of reach (diagnostic, ~0)
};

Synthesis Synthesize(const ClipScript& script, const Skeleton& skeleton = Skeleton::Smpl22());

}  // namespace motionpipe::corpus
