// Builds SMPL-22 local rotations from body targets: pelvis placement, spine/neck/head angles, and
// world targets for the ankles and wrists solved by two-bone IK. Knees and elbows come out as pure
// hinge rotations (knee about its x axis, elbow about its y axis, as in SMPL), so the anatomy is
// right by construction; bone lengths are the skeleton's (FK), so they never change.
#pragma once

#include <array>

#include "motionpipe/math/rotation.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {

// Body-frame angle triple: x = bend forward (pitch), y = turn left (twist), z = lean right (roll),
// radians; applied as R = Ry(y) Rx(x) Rz(z).
Mat3 BodyAngles(const Vec3& angles);

struct FootTarget {
  Vec3 ankle;      // world position of the ankle joint
  Vec3 toe_dir;    // unit world direction ankle -> foot joint (horizontal when the foot is flat)
  Vec3 knee_pole;  // world direction the knee points to (forward)
};

struct HandTarget {
  Vec3 wrist;               // world position of the wrist joint
  Vec3 elbow_pole;          // world direction the elbow points to (down/back/out for a relaxed arm)
  double collar_raise = 0;  // radians: shoulder shrug
  Vec3 wrist_angles;        // local wrist rotation (body-angle triple)
};

struct PoseTargets {
  Vec3 pelvis;                // world position of the pelvis joint
  double facing = 0;          // radians: the body faces (cos, sin, 0)
  Vec3 pelvis_angles;         // body-frame tilt of the pelvis
  std::array<Vec3, 3> spine;  // spine1, spine2, spine3 local angles
  Vec3 neck;
  Vec3 head;
  std::array<FootTarget, 2> feet;   // left, right
  std::array<HandTarget, 2> hands;  // left, right
};

struct SolvedPose {
  std::array<Mat3, kNumJoints> local;
  Vec3 translation;
  std::array<double, 2>
      leg_reach_error{};  // metres the ankle target was out of reach (0 = reached)
  std::array<double, 2> arm_reach_error{};
};

// Global orientation of the pelvis for a facing angle and tilt: Rz(facing + pi/2) Rx(pi/2) tilt.
Mat3 PelvisOrientation(double facing, const Vec3& angles);

SolvedPose SolvePose(const Skeleton& skeleton, const PoseTargets& targets);

// The upper body's frame before the arms are solved: spine3's global rotation and position and
// both shoulder joints (collar shrugs applied). Hand targets are placed relative to these.
struct UpperBodyFrame {
  Mat3 chest;
  Vec3 chest_position;
  std::array<Vec3, 2> shoulders;
};
UpperBodyFrame ComputeUpperBody(const Skeleton& skeleton, const PoseTargets& targets);

// World position of the hip joints and shoulders for a pelvis placement: what planners need to keep
// targets in reach without running the whole solver. `side` 0 = left, 1 = right.
Vec3 HipPosition(const Skeleton& skeleton, const Vec3& pelvis, const Mat3& pelvis_orientation,
                 int side);

}  // namespace motionpipe
