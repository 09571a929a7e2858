#include "motionpipe/skeleton/skeleton.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "smpl22_json.h"  // generated: kSmpl22Json

namespace motionpipe {

const std::array<std::string, kNumBodyParts>& BodyPartNames() {
  static const std::array<std::string, kNumBodyParts> names = {
      "global", "torso", "left arm", "right arm", "left leg", "right leg"};
  return names;
}

std::string PartSetToString(PartSet parts) {
  std::string out;
  for (int part = 0; part < kNumBodyParts; ++part) {
    if (!(parts & (1u << part))) continue;
    if (!out.empty()) out += "+";
    out += BodyPartNames()[static_cast<size_t>(part)];
  }
  return out.empty() ? "none" : out;
}

int PartCount(PartSet parts) {
  int count = 0;
  for (int part = 0; part < kNumBodyParts; ++part) count += (parts >> part) & 1;
  return count;
}

const Skeleton& Skeleton::Smpl22() {
  static const Skeleton skeleton = [] {
    auto parsed = FromJson(kSmpl22Json, "embedded smpl22.json");
    if (!parsed.ok()) std::abort();  // the embedded file is part of the build; tests cover it
    return std::move(parsed).value();
  }();
  return skeleton;
}

namespace {
Status Bad(const std::string& origin, const std::string& what) {
  return DataLoss(origin + ": " + what);
}
}  // namespace

Result<Skeleton> Skeleton::FromJson(const std::string& json_text, const std::string& origin,
                                    RestPose rest_pose) {
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(json_text);
  } catch (const nlohmann::json::exception& error) {
    return Bad(origin, std::string("malformed JSON: ") + error.what());
  }
  Skeleton s;
  try {
    s.joint_names_ = doc.at("joint_names").get<std::vector<std::string>>();
    s.parents_ = doc.at("parents").get<std::vector<int>>();
    const auto directions =
        doc.at("rest_offset_directions_yup").get<std::vector<std::vector<double>>>();
    s.bone_lengths_ = doc.at("bone_lengths_m").get<std::vector<double>>();
    s.chains_ = doc.at("kinematic_chains").get<std::vector<std::vector<int>>>();
    if (s.joint_names_.size() != kNumJoints) return Bad(origin, "joint_names must list 22 joints");
    if (s.parents_.size() != kNumJoints || directions.size() != kNumJoints ||
        s.bone_lengths_.size() != kNumJoints) {
      return Bad(origin, "parents, rest_offset_directions_yup and bone_lengths_m need 22 entries");
    }
    for (int joint = 0; joint < kNumJoints; ++joint) {
      const int parent = s.parents_[static_cast<size_t>(joint)];
      if ((joint == 0 && parent != -1) || (joint > 0 && (parent < 0 || parent >= joint))) {
        return Bad(origin, "parents[" + std::to_string(joint) + "] must precede the joint");
      }
      const auto& d = directions[static_cast<size_t>(joint)];
      if (d.size() != 3)
        return Bad(origin, "rest direction " + std::to_string(joint) + " needs 3 values");
      Vec3 dir{d[0], d[1], d[2]};
      const double n = Norm(dir);
      if (joint > 0 && n == 0)
        return Bad(origin, "rest direction " + std::to_string(joint) + " is zero");
      if (n > 0) dir = (1.0 / n) * dir;
      s.rest_offsets_.push_back(s.bone_lengths_[static_cast<size_t>(joint)] * dir);
    }
    const auto& parts = doc.at("sinc_body_parts").at("joints");
    for (int part = 0; part < kNumBodyParts; ++part) {
      const auto& name = BodyPartNames()[static_cast<size_t>(part)];
      s.part_joints_[static_cast<size_t>(part)] = parts.at(name).get<std::vector<int>>();
      for (int joint : s.part_joints_[static_cast<size_t>(part)]) {
        if (joint < 0 || joint >= kNumJoints)
          return Bad(origin, "body part '" + name + "' has bad joint");
        s.joint_part_[static_cast<size_t>(joint)] = static_cast<BodyPart>(part);
      }
    }
    if (doc.contains("feet_joints")) {
      const auto left = doc["feet_joints"].at("left").get<std::vector<int>>();
      const auto right = doc["feet_joints"].at("right").get<std::vector<int>>();
      if (left.size() != 2 || right.size() != 2)
        return Bad(origin, "feet_joints needs two per side");
      s.left_feet_ = {left[0], left[1]};
      s.right_feet_ = {right[0], right[1]};
    }
  } catch (const nlohmann::json::exception& error) {
    return Bad(origin, std::string("missing or mistyped field: ") + error.what());
  }
  if (rest_pose == RestPose::kSmplTPose) {
    // The file's directions are HumanML3D's IK conventions; SMPL's rest geometry differs in two
    // places. The head sits above the neck, not in front of it.
    const int head = s.JointIndex("head");
    if (head < 0) return Bad(origin, "missing joint head");
    s.rest_offsets_[static_cast<size_t>(head)] =
        Vec3{0, s.bone_lengths_[static_cast<size_t>(head)], 0};
    // And the arm chain points sideways: SMPL pose parameters are relative to the T-pose.
    for (const char* side : {"left", "right"}) {
      const double sign = std::string(side) == "left" ? 1.0 : -1.0;
      for (const char* joint : {"_shoulder", "_elbow", "_wrist"}) {
        const int index = s.JointIndex(std::string(side) + joint);
        if (index < 0) return Bad(origin, std::string("missing joint ") + side + joint);
        s.rest_offsets_[static_cast<size_t>(index)] =
            Vec3{sign * s.bone_lengths_[static_cast<size_t>(index)], 0, 0};
      }
    }
  }
  return s;
}

int Skeleton::JointIndex(const std::string& name) const {
  const auto it = std::find(joint_names_.begin(), joint_names_.end(), name);
  return it == joint_names_.end() ? -1 : static_cast<int>(it - joint_names_.begin());
}

double Skeleton::RestPelvisHeight() const {
  std::array<Vec3, kNumJoints> positions{};
  double lowest = 0;
  for (int joint = 1; joint < kNumJoints; ++joint) {
    positions[static_cast<size_t>(joint)] =
        positions[static_cast<size_t>(parents_[static_cast<size_t>(joint)])] +
        rest_offsets_[static_cast<size_t>(joint)];
  }
  for (int joint : {left_feet_[0], left_feet_[1], right_feet_[0], right_feet_[1]}) {
    lowest = std::min(lowest, positions[static_cast<size_t>(joint)].y);
  }
  return -lowest;
}

Mat3 YUpToZUp() { return RotX(kPi / 2); }

void ForwardKinematicsFrame(const Skeleton& skeleton, const Mat3* local, const Vec3& root,
                            Mat3* global_out, Vec3* positions_out) {
  const auto& parents = skeleton.parents();
  const auto& offsets = skeleton.rest_offsets();
  global_out[0] = local[0];
  positions_out[0] = root;
  for (int joint = 1; joint < kNumJoints; ++joint) {
    const int parent = parents[static_cast<size_t>(joint)];
    global_out[joint] = global_out[parent] * local[joint];
    positions_out[joint] =
        positions_out[parent] + global_out[parent] * offsets[static_cast<size_t>(joint)];
  }
}

}  // namespace motionpipe
