// The SMPL 22-joint body (SMPL/SMPL-H without hands) used by AMASS, BABEL, MotionFix and SINC, and
// forward kinematics on it. Facts come from data/skeleton/smpl22.json (embedded in the binary).
//
// Frames: rest offsets live in SMPL's y-up body frame (x = the body's left, z = forward); motions
// live in the z-up world of AMASS (metres), so a standing body has a global orientation of about
// Rx(+90 deg).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/math/rotation.h"

namespace motionpipe {

constexpr int kNumJoints = 22;
constexpr int kNumBodyParts = 6;

// SINC's body-part vector order (REFERENCE.md 4.1).
enum class BodyPart : int { kGlobal = 0, kTorso, kLeftArm, kRightArm, kLeftLeg, kRightLeg };

// A set of body parts as a bit mask (bit i = BodyPart i).
using PartSet = uint8_t;
constexpr PartSet PartBit(BodyPart part) {
  return static_cast<PartSet>(1u << static_cast<int>(part));
}
const std::array<std::string, kNumBodyParts>& BodyPartNames();
// "global+left arm" style; "none" for the empty set.
std::string PartSetToString(PartSet parts);
int PartCount(PartSet parts);

// Which rest directions the offsets use.
enum class RestPose {
  // SMPL's T-pose: the file's directions, except where HumanML3D's IK conventions differ from
  // SMPL's
  // rest geometry: the arm chain (shoulder, elbow, wrist offsets) points sideways (+x left, -x
  // right),
  // because AMASS/MotionFix pose parameters are rotations relative to SMPL's T-pose, and the head
  // sits above the neck (+y) instead of in front of it. Lengths are always the file's. The default.
  kSmplTPose,
  // The file's raw HumanML3D IK directions (arms hanging down).
  kFileDirections,
};

class Skeleton {
 public:
  // The embedded SMPL-22 skeleton.
  static const Skeleton& Smpl22();
  // Parses a skeleton JSON in the layout of data/skeleton/smpl22.json. DataLoss names the file and
  // the bad field.
  static Result<Skeleton> FromJson(const std::string& json_text, const std::string& origin,
                                   RestPose rest_pose = RestPose::kSmplTPose);

  const std::vector<std::string>& joint_names() const { return joint_names_; }
  const std::vector<int>& parents() const { return parents_; }
  // Rest offset of each joint from its parent, y-up body frame, metres (zero for the root).
  const std::vector<Vec3>& rest_offsets() const { return rest_offsets_; }
  const std::vector<double>& bone_lengths() const { return bone_lengths_; }
  const std::vector<std::vector<int>>& kinematic_chains() const { return chains_; }
  // Joints of each body part, in BodyPart order.
  const std::array<std::vector<int>, kNumBodyParts>& part_joints() const { return part_joints_; }
  // Body part owning each joint.
  BodyPart part_of_joint(int joint) const { return joint_part_[static_cast<size_t>(joint)]; }
  const std::array<int, 2>& left_foot_joints() const { return left_feet_; }
  const std::array<int, 2>& right_foot_joints() const { return right_feet_; }
  // Index of a joint by name, or -1.
  int JointIndex(const std::string& name) const;
  // Vertical distance from the pelvis to the lowest foot joint in the rest pose (metres).
  double RestPelvisHeight() const;

 private:
  std::vector<std::string> joint_names_;
  std::vector<int> parents_;
  std::vector<Vec3> rest_offsets_;
  std::vector<double> bone_lengths_;
  std::vector<std::vector<int>> chains_;
  std::array<std::vector<int>, kNumBodyParts> part_joints_;
  std::array<BodyPart, kNumJoints> joint_part_{};
  std::array<int, 2> left_feet_{7, 10};
  std::array<int, 2> right_feet_{8, 11};
};

// Rotation from SMPL's y-up body/world frame to the z-up world of AMASS: Rx(+90 deg) (y -> z).
Mat3 YUpToZUp();

// Forward kinematics of one frame. `local` holds the 22 local rotations (joint 0 = global
// orientation); writes 22 global rotations and 22 world positions (pelvis at `root`).
void ForwardKinematicsFrame(const Skeleton& skeleton, const Mat3* local, const Vec3& root,
                            Mat3* global_out, Vec3* positions_out);

}  // namespace motionpipe
