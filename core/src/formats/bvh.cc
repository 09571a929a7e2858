#include "motionpipe/formats/bvh.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "motionpipe/base/file.h"

namespace motionpipe {

namespace {

constexpr int kMaxBvhJoints = 4096;
constexpr double kDegToRad = kPi / 180.0;

// Whitespace tokenizer that remembers line numbers for error messages.
class Tokens {
 public:
  explicit Tokens(std::string_view text) : text_(text) {}
  bool Next(std::string_view* token) {
    while (pos_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[pos_]))) {
      if (text_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ >= text_.size()) return false;
    const size_t start = pos_;
    while (pos_ < text_.size() && !std::isspace(static_cast<unsigned char>(text_[pos_]))) ++pos_;
    *token = text_.substr(start, pos_ - start);
    return true;
  }
  int line() const { return line_; }

 private:
  std::string_view text_;
  size_t pos_ = 0;
  int line_ = 1;
};

bool ParseDouble(std::string_view token, double* out) {
  if (token.empty() || token.size() > 64) return false;
  char buffer[65];
  std::copy(token.begin(), token.end(), buffer);
  buffer[token.size()] = '\0';
  char* end = nullptr;
  *out = std::strtod(buffer, &end);
  return end == buffer + token.size() && std::isfinite(*out);
}

bool ParseChannel(std::string_view token, BvhChannel* channel) {
  std::string lower;
  for (char c : token)
    lower.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  static const std::pair<const char*, BvhChannel> kNames[] = {
      {"xposition", BvhChannel::kXpos}, {"yposition", BvhChannel::kYpos},
      {"zposition", BvhChannel::kZpos}, {"xrotation", BvhChannel::kXrot},
      {"yrotation", BvhChannel::kYrot}, {"zrotation", BvhChannel::kZrot}};
  for (const auto& [name, value] : kNames) {
    if (lower == name) {
      *channel = value;
      return true;
    }
  }
  return false;
}

std::string StripNamespace(const std::string& name) {
  const size_t colon = name.rfind(':');
  return colon == std::string::npos ? name : name.substr(colon + 1);
}

}  // namespace

int BvhFile::JointIndex(const std::string& name) const {
  for (size_t k = 0; k < joints.size(); ++k) {
    if (joints[k].name == name) return static_cast<int>(k);
  }
  for (size_t k = 0; k < joints.size(); ++k) {
    if (StripNamespace(joints[k].name) == StripNamespace(name)) return static_cast<int>(k);
  }
  return -1;
}

Result<BvhFile> ParseBvh(std::string_view text, const std::string& origin) {
  Tokens tokens(text);
  std::string_view token;
  BvhFile bvh;
  const auto fail = [&](const std::string& what) {
    return DataLoss(origin + ":" + std::to_string(tokens.line()) + ": " + what);
  };
  const auto expect_number = [&](double* out, const char* what) -> Status {
    if (!tokens.Next(&token)) return fail(std::string("file ends before ") + what);
    if (!ParseDouble(token, out))
      return fail(std::string("expected a number for ") + what + ", found '" + std::string(token) +
                  "'");
    return Status::Ok();
  };
  if (!tokens.Next(&token) || token != "HIERARCHY")
    return fail("expected 'HIERARCHY' at the start");
  std::vector<int> stack;  // open joints; -2 marks an End Site block
  int channel_count = 0;
  bool seen_root = false;
  while (true) {
    if (!tokens.Next(&token))
      return fail("file ends inside the hierarchy (missing MOTION section)");
    if (token == "ROOT" || token == "JOINT") {
      if (token == "ROOT" && (seen_root || !stack.empty()))
        return fail("second ROOT (only one skeleton per file is supported)");
      if (token == "JOINT" && (stack.empty() || stack.back() < 0))
        return fail("JOINT outside a parent joint");
      seen_root = true;
      BvhJoint joint;
      if (!tokens.Next(&token)) return fail("joint without a name");
      joint.name = std::string(token);
      joint.parent = stack.empty() ? -1 : stack.back();
      if (!tokens.Next(&token) || token != "{")
        return fail("expected '{' after joint '" + joint.name + "'");
      if (!tokens.Next(&token) || token != "OFFSET")
        return fail("expected OFFSET in joint '" + joint.name + "'");
      MP_RETURN_IF_ERROR(expect_number(&joint.offset.x, "OFFSET"));
      MP_RETURN_IF_ERROR(expect_number(&joint.offset.y, "OFFSET"));
      MP_RETURN_IF_ERROR(expect_number(&joint.offset.z, "OFFSET"));
      if (!tokens.Next(&token) || token != "CHANNELS")
        return fail("expected CHANNELS in joint '" + joint.name + "'");
      double count = 0;
      MP_RETURN_IF_ERROR(expect_number(&count, "the channel count"));
      if (count < 0 || count > 6 || count != std::floor(count))
        return fail("channel count must be 0..6 in joint '" + joint.name + "'");
      joint.first_channel = channel_count;
      for (int c = 0; c < static_cast<int>(count); ++c) {
        BvhChannel channel{};
        if (!tokens.Next(&token) || !ParseChannel(token, &channel)) {
          return fail("joint '" + joint.name + "' declares " +
                      std::to_string(static_cast<int>(count)) + " channels but channel " +
                      std::to_string(c + 1) + " is not a channel name");
        }
        joint.channels.push_back(channel);
        if (channel >= BvhChannel::kXrot) {
          joint.rotation_order.push_back(static_cast<char>(
              'X' + (static_cast<int>(channel) - static_cast<int>(BvhChannel::kXrot))));
        }
      }
      if (!joint.rotation_order.empty() && !EulerOrderValid(joint.rotation_order)) {
        return fail("joint '" + joint.name + "' rotation channels must name X, Y and Z once each");
      }
      channel_count += static_cast<int>(count);
      if (static_cast<int>(bvh.joints.size()) >= kMaxBvhJoints)
        return fail("more than 4096 joints");
      bvh.joints.push_back(std::move(joint));
      stack.push_back(static_cast<int>(bvh.joints.size()) - 1);
    } else if (token == "End") {
      if (!tokens.Next(&token) || token != "Site") return fail("expected 'End Site'");
      if (stack.empty() || stack.back() < 0) return fail("End Site outside a joint");
      BvhJoint& owner = bvh.joints[static_cast<size_t>(stack.back())];
      if (!tokens.Next(&token) || token != "{") return fail("expected '{' after End Site");
      if (!tokens.Next(&token) || token != "OFFSET") return fail("expected OFFSET in End Site");
      MP_RETURN_IF_ERROR(expect_number(&owner.end_site.x, "End Site OFFSET"));
      MP_RETURN_IF_ERROR(expect_number(&owner.end_site.y, "End Site OFFSET"));
      MP_RETURN_IF_ERROR(expect_number(&owner.end_site.z, "End Site OFFSET"));
      owner.has_end_site = true;
      if (!tokens.Next(&token) || token != "}") return fail("expected '}' closing End Site");
    } else if (token == "}") {
      if (stack.empty()) return fail("unbalanced '}'");
      stack.pop_back();
    } else if (token == "MOTION") {
      if (!stack.empty()) return fail("MOTION before the hierarchy is closed (missing '}')");
      break;
    } else {
      return fail("unexpected '" + std::string(token) + "' in the hierarchy");
    }
  }
  if (bvh.joints.empty()) return fail("no ROOT joint");
  bvh.channels_per_frame = channel_count;
  if (!tokens.Next(&token) || token != "Frames:") return fail("expected 'Frames:'");
  double frames = 0;
  MP_RETURN_IF_ERROR(expect_number(&frames, "the frame count"));
  if (frames < 0 || frames != std::floor(frames) || frames > 1e8) return fail("bad frame count");
  bvh.frames = static_cast<int64_t>(frames);
  if (!tokens.Next(&token) || token != "Frame") return fail("expected 'Frame Time:'");
  if (!tokens.Next(&token) || token != "Time:") return fail("expected 'Frame Time:'");
  MP_RETURN_IF_ERROR(expect_number(&bvh.frame_time, "the frame time"));
  if (!(bvh.frame_time > 0)) return fail("frame time must be positive");
  const int64_t expected = bvh.frames * channel_count;
  // Values are never more than the text can hold: guard the reservation against bogus counts.
  if (static_cast<uint64_t>(expected) > text.size()) {
    return fail("file declares " + std::to_string(bvh.frames) + " frames of " +
                std::to_string(channel_count) +
                " channels but is too short to hold them (truncated)");
  }
  bvh.values.reserve(static_cast<size_t>(expected));
  for (int64_t k = 0; k < expected; ++k) {
    if (!tokens.Next(&token)) {
      return fail("truncated motion: frame " + std::to_string(k / std::max(channel_count, 1) + 1) +
                  " of " + std::to_string(bvh.frames) + " is incomplete (" +
                  std::to_string(channel_count) + " channels per frame)");
    }
    double value = 0;
    if (!ParseDouble(token, &value))
      return fail("non-numeric motion value '" + std::string(token) + "'");
    bvh.values.push_back(static_cast<float>(value));
  }
  if (tokens.Next(&token)) {
    return fail("more motion values than " + std::to_string(bvh.frames) + " frames x " +
                std::to_string(channel_count) + " channels (wrong channel count or frame count)");
  }
  return bvh;
}

Result<BvhFile> ReadBvh(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(path));
  return ParseBvh(text, path);
}

void BvhForwardKinematics(const BvhFile& bvh, int64_t frame, std::vector<Mat3>* global,
                          std::vector<Vec3>* positions) {
  const size_t n = bvh.joints.size();
  global->assign(n, Mat3::Identity());
  positions->assign(n, Vec3{});
  const float* row = bvh.values.data() + frame * bvh.channels_per_frame;
  for (size_t k = 0; k < n; ++k) {
    const BvhJoint& joint = bvh.joints[k];
    Vec3 translation = joint.offset;
    std::array<double, 3> angles{};
    int rot = 0;
    for (size_t c = 0; c < joint.channels.size(); ++c) {
      const double v = row[joint.first_channel + static_cast<int>(c)];
      switch (joint.channels[c]) {
        // Position channels give the joint's translation from its parent and replace the offset.
        case BvhChannel::kXpos:
          translation.x = v;
          break;
        case BvhChannel::kYpos:
          translation.y = v;
          break;
        case BvhChannel::kZpos:
          translation.z = v;
          break;
        default:
          angles[static_cast<size_t>(rot++)] = v * kDegToRad;
          break;
      }
    }
    const Mat3 local = joint.rotation_order.empty() ? Mat3::Identity()
                                                    : EulerToMatrix(joint.rotation_order, angles);
    if (joint.parent < 0) {
      (*global)[k] = local;
      (*positions)[k] = translation;
    } else {
      const auto parent = static_cast<size_t>(joint.parent);
      (*global)[k] = (*global)[parent] * local;
      (*positions)[k] = (*positions)[parent] + (*global)[parent] * translation;
    }
  }
}

const std::vector<JointMap>& BuiltinJointMaps() {
  static const std::vector<JointMap> maps = [] {
    std::vector<JointMap> out;
    // Order follows data/skeleton/smpl22.json joint_names.
    out.push_back(
        {"cmu",
         {"Hips",      "LeftHip",    "RightHip",    "lowerback", "LeftKnee",     "RightKnee",
          "Chest",     "LeftAnkle",  "RightAnkle",  "Chest2",    "LeftToe",      "RightToe",
          "Neck",      "LeftCollar", "RightCollar", "Head",      "LeftShoulder", "RightShoulder",
          "LeftElbow", "RightElbow", "LeftWrist",   "RightWrist"},
         0.056444});
    JointMap smpl{"smpl22", {}, 0.0};
    for (int j = 0; j < kNumJoints; ++j)
      smpl.source[static_cast<size_t>(j)] =
          Skeleton::Smpl22().joint_names()[static_cast<size_t>(j)];
    out.push_back(smpl);
    out.push_back({"mixamo",
                   {"mixamorig:Hips",        "mixamorig:LeftUpLeg",    "mixamorig:RightUpLeg",
                    "mixamorig:Spine",       "mixamorig:LeftLeg",      "mixamorig:RightLeg",
                    "mixamorig:Spine1",      "mixamorig:LeftFoot",     "mixamorig:RightFoot",
                    "mixamorig:Spine2",      "mixamorig:LeftToeBase",  "mixamorig:RightToeBase",
                    "mixamorig:Neck",        "mixamorig:LeftShoulder", "mixamorig:RightShoulder",
                    "mixamorig:Head",        "mixamorig:LeftArm",      "mixamorig:RightArm",
                    "mixamorig:LeftForeArm", "mixamorig:RightForeArm", "mixamorig:LeftHand",
                    "mixamorig:RightHand"},
                   0.0});
    return out;
  }();
  return maps;
}

Result<JointMap> ParseJointMap(const std::string& text, const std::string& origin) {
  JointMap map;
  map.name = origin;
  const Skeleton& smpl = Skeleton::Smpl22();
  std::istringstream in(text);
  std::string line;
  int line_number = 0;
  const auto trim = [](std::string s) {
    const size_t b = s.find_first_not_of(" \t\r\"'");
    const size_t e = s.find_last_not_of(" \t\r\"'");
    return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
  };
  while (std::getline(in, line)) {
    ++line_number;
    if (const size_t hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    if (trim(line).empty()) continue;
    // The separator is the first ": " or the first ':' when the value holds namespaces.
    size_t colon = line.find(": ");
    if (colon == std::string::npos) colon = line.find(':');
    if (colon == std::string::npos) {
      return DataLoss(origin + ":" + std::to_string(line_number) +
                      ": expected 'smpl_joint: source_joint'");
    }
    const std::string key = trim(line.substr(0, colon));
    const std::string value = trim(line.substr(colon + 1));
    if (key == "unit_scale") {
      char* end = nullptr;
      map.unit_scale = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0' || !(map.unit_scale > 0)) {
        return DataLoss(origin + ":" + std::to_string(line_number) +
                        ": unit_scale must be a positive number");
      }
      continue;
    }
    const int joint = smpl.JointIndex(key);
    if (joint < 0) {
      return DataLoss(origin + ":" + std::to_string(line_number) + ": '" + key +
                      "' is not an SMPL-22 joint name");
    }
    if (value.empty())
      return DataLoss(origin + ":" + std::to_string(line_number) + ": no source joint for '" + key +
                      "'");
    map.source[static_cast<size_t>(joint)] = value;
  }
  std::string missing;
  for (int j = 0; j < kNumJoints; ++j) {
    if (map.source[static_cast<size_t>(j)].empty())
      missing += (missing.empty() ? "" : ", ") + smpl.joint_names()[static_cast<size_t>(j)];
  }
  if (!missing.empty()) return DataLoss(origin + ": the map does not list SMPL joints: " + missing);
  return map;
}

Result<JointMap> ChooseJointMap(const BvhFile& bvh, const std::string& origin) {
  const JointMap* closest = nullptr;
  std::string closest_missing;
  size_t fewest = SIZE_MAX;
  for (const JointMap& map : BuiltinJointMaps()) {
    std::string missing;
    size_t count = 0;
    for (int j = 0; j < kNumJoints; ++j) {
      if (bvh.JointIndex(map.source[static_cast<size_t>(j)]) < 0) {
        missing += (missing.empty() ? "" : ", ") +
                   Skeleton::Smpl22().joint_names()[static_cast<size_t>(j)] + " (" +
                   map.source[static_cast<size_t>(j)] + ")";
        ++count;
      }
    }
    if (count == 0) return map;
    if (count < fewest) {
      fewest = count;
      closest = &map;
      closest_missing = missing;
    }
  }
  return InvalidArgument(origin +
                         ": cannot map this skeleton onto SMPL-22; the closest built-in map ('" +
                         closest->name + "') lacks the SMPL joints " + closest_missing +
                         ". Pass --map FILE with 'smpl_joint: your_joint' lines");
}

namespace {

// The SMPL child that defines each joint's bone direction (-1: leaf).
constexpr std::array<int, kNumJoints> kPrimaryChild = {3,  4,  5,  6,  7,  8,  9,  10, 11, 12, -1,
                                                       -1, 15, 16, 17, -1, 18, 19, 20, 21, -1, -1};

// A hint perpendicular enough to `direction` to fix the twist about it: forward, else up.
Vec3 TwistHint(const Vec3& direction) {
  const Vec3 forward{0, 0, 1};
  return std::abs(Dot(forward, (1.0 / Norm(direction)) * direction)) < 0.9 ? forward
                                                                           : Vec3{0, 1, 0};
}

// Conventional direction of leaf bones in SMPL's rest frame (head up, feet forward, hands outward).
Vec3 LeafDirection(const Skeleton& skeleton, int joint) {
  const std::string& name = skeleton.joint_names()[static_cast<size_t>(joint)];
  if (name == "head") return {0, 1, 0};
  if (name == "left_wrist") return {1, 0, 0};
  if (name == "right_wrist") return {-1, 0, 0};
  return {0, 0, 1};  // feet
}

using JointIndices = std::array<int, kNumJoints>;  // SMPL joint -> source joint index

// The source joint of each SMPL joint under `map`; the mapped joints must keep SMPL's ancestry, or
// rotations cannot be related.
Result<JointIndices> MapJoints(const BvhFile& bvh, const JointMap& map, const std::string& origin,
                               const Skeleton& skeleton) {
  JointIndices source_of{};
  std::string missing;
  for (int j = 0; j < kNumJoints; ++j) {
    source_of[static_cast<size_t>(j)] = bvh.JointIndex(map.source[static_cast<size_t>(j)]);
    if (source_of[static_cast<size_t>(j)] < 0)
      missing += (missing.empty() ? "" : ", ") + map.source[static_cast<size_t>(j)];
  }
  if (!missing.empty())
    return InvalidArgument(origin + ": joints named in map '" + map.name +
                           "' are absent: " + missing);
  for (int j = 1; j < kNumJoints; ++j) {
    int ancestor = bvh.joints[static_cast<size_t>(source_of[static_cast<size_t>(j)])].parent;
    const int wanted = source_of[static_cast<size_t>(skeleton.parents()[static_cast<size_t>(j)])];
    while (ancestor >= 0 && ancestor != wanted)
      ancestor = bvh.joints[static_cast<size_t>(ancestor)].parent;
    if (ancestor != wanted) {
      return InvalidArgument(
          origin + ": source joint '" + map.source[static_cast<size_t>(j)] +
          "' is not a descendant of '" +
          map.source[static_cast<size_t>(skeleton.parents()[static_cast<size_t>(j)])] + "'");
    }
  }
  return source_of;
}

// The source's rest pose: every joint's position with all rotations identity, offsets only.
std::vector<Vec3> RestPositions(const BvhFile& bvh) {
  std::vector<Vec3> rest(bvh.joints.size());
  for (size_t k = 0; k < bvh.joints.size(); ++k) {
    const BvhJoint& joint = bvh.joints[k];
    rest[k] =
        joint.parent < 0 ? joint.offset : rest[static_cast<size_t>(joint.parent)] + joint.offset;
  }
  return rest;
}

// Step (1): per SMPL joint, the rotation taking its rest bone onto the source's rest bone, with
// the twist fixed by the body frame read off the rest pose (left = hips, up = spine).
Result<std::array<Mat3, kNumJoints>> RestAlignment(const BvhFile& bvh,
                                                   const JointIndices& source_of,
                                                   const std::vector<Vec3>& rest,
                                                   const std::string& origin,
                                                   const Skeleton& skeleton) {
  const auto rest_of = [&](int smpl_joint) {
    return rest[static_cast<size_t>(source_of[static_cast<size_t>(smpl_joint)])];
  };
  const Vec3 source_left = rest_of(1) - rest_of(2);
  const Vec3 source_up = rest_of(9) - rest_of(0);
  if (Norm(source_left) < 1e-9 || Norm(source_up) < 1e-9 ||
      Norm(Cross(source_left, source_up)) < 1e-9) {
    return InvalidArgument(
        origin +
        ": cannot read the body's orientation from the rest pose (hips or spine degenerate)");
  }
  const Mat3 body = RotationFromTwoDirections({0, 1, 0}, {1, 0, 0}, source_up, source_left);
  std::array<Mat3, kNumJoints> align{};
  for (int j = 0; j < kNumJoints; ++j) {
    const int child = kPrimaryChild[static_cast<size_t>(j)];
    Vec3 smpl_dir, source_dir;
    if (child >= 0) {
      smpl_dir = skeleton.rest_offsets()[static_cast<size_t>(child)];
      source_dir = rest_of(child) - rest_of(j);
    } else {
      const BvhJoint& leaf = bvh.joints[static_cast<size_t>(source_of[static_cast<size_t>(j)])];
      smpl_dir = LeafDirection(skeleton, j);
      source_dir = Vec3{};
      if (leaf.has_end_site) source_dir = leaf.end_site;
      for (size_t k = 0; k < bvh.joints.size() && Norm(source_dir) < 1e-9; ++k) {
        if (bvh.joints[k].parent == source_of[static_cast<size_t>(j)])
          source_dir = bvh.joints[k].offset;
      }
    }
    if (Norm(source_dir) < 1e-9 || Norm(smpl_dir) < 1e-9) {
      align[static_cast<size_t>(j)] =
          body;  // zero-length source bone: only the body frame is known
      continue;
    }
    const Vec3 hint = TwistHint(smpl_dir);
    Vec3 source_hint = body * hint;
    if (Norm(Cross(source_hint, source_dir)) < 1e-6 * Norm(source_dir))
      source_hint = body * Vec3{1, 0, 0};
    align[static_cast<size_t>(j)] =
        RotationFromTwoDirections(smpl_dir, hint, source_dir, source_hint);
  }
  return align;
}

// Root motion: by default scaled by the ratio of leg lengths (stride and pelvis height follow the
// SMPL body, so feet neither slide nor sink); optionally in true metres via the unit scale.
Result<double> RootScale(const JointIndices& source_of, const std::vector<Vec3>& rest,
                         const JointMap& map, const BvhImportOptions& options,
                         const std::string& origin, const Skeleton& skeleton) {
  const auto rest_of = [&](int smpl_joint) {
    return rest[static_cast<size_t>(source_of[static_cast<size_t>(smpl_joint)])];
  };
  const double source_leg = Norm(rest_of(4) - rest_of(1)) + Norm(rest_of(7) - rest_of(4));
  const double smpl_leg = skeleton.bone_lengths()[4] + skeleton.bone_lengths()[7];
  if (source_leg < 1e-9)
    return InvalidArgument(origin + ": the left leg has zero length in the rest pose");
  if (options.scale_root_to_leg) return smpl_leg / source_leg;
  const double root_scale = options.unit_scale > 0 ? options.unit_scale : map.unit_scale;
  if (root_scale <= 0) {
    return InvalidArgument(origin +
                           ": the metres-per-unit scale of this rig is unknown; pass a unit scale");
  }
  return root_scale;
}

// Steps (2) and (3), per frame: each SMPL bone swung onto the source bone between the mapped
// joints' actual positions, keeping the twist; the root moved with the source root, scaled; y-up
// turned into z-up.
void RetargetFrames(const BvhFile& bvh, const JointIndices& source_of,
                    const std::array<Mat3, kNumJoints>& align, double root_scale,
                    const Skeleton& skeleton, Motion* motion) {
  motion->fps = 1.0 / bvh.frame_time;
  motion->poses.resize(static_cast<size_t>(bvh.frames) * kNumJoints * 3);
  motion->trans.resize(static_cast<size_t>(bvh.frames) * 3);
  const Mat3 up = YUpToZUp();
  std::vector<Mat3> source_global;
  std::vector<Vec3> source_pos;
  std::array<Mat3, kNumJoints> global{};
  for (int64_t frame = 0; frame < bvh.frames; ++frame) {
    BvhForwardKinematics(bvh, frame, &source_global, &source_pos);
    for (int j = 0; j < kNumJoints; ++j) {
      const auto src = static_cast<size_t>(source_of[static_cast<size_t>(j)]);
      Mat3 g = source_global[src] * align[static_cast<size_t>(j)];
      const int child = kPrimaryChild[static_cast<size_t>(j)];
      if (child >= 0) {
        const Vec3 target = source_pos[static_cast<size_t>(source_of[static_cast<size_t>(child)])] -
                            source_pos[src];
        if (Norm(target) > 1e-9)
          g = RotationBetween(g * skeleton.rest_offsets()[static_cast<size_t>(child)], target) * g;
      }
      global[static_cast<size_t>(j)] = g;
    }
    for (int j = 0; j < kNumJoints; ++j) {
      const Mat3 local =
          j == 0
              ? up * global[0]
              : Transpose(global[static_cast<size_t>(skeleton.parents()[static_cast<size_t>(j)])]) *
                    global[static_cast<size_t>(j)];
      motion->SetLocalRotation(frame, j, local);
    }
    motion->SetTranslation(frame,
                           up * (root_scale * source_pos[static_cast<size_t>(source_of[0])]));
  }
}

// Step (4): the feet on z = 0, at the 5th percentile of the per-frame lowest foot joint (robust to
// jumps and to a few bad frames).
void PlaceOnFloor(const Skeleton& skeleton, Motion* motion) {
  const std::vector<float> joints = ComputeJoints(skeleton, *motion);
  std::vector<float> lowest;
  for (int64_t frame = 0; frame < motion->num_frames(); ++frame) {
    float low = 1e30f;
    for (int j : {skeleton.left_foot_joints()[0], skeleton.left_foot_joints()[1],
                  skeleton.right_foot_joints()[0], skeleton.right_foot_joints()[1]}) {
      low = std::min(low, joints[static_cast<size_t>((frame * kNumJoints + j) * 3 + 2)]);
    }
    lowest.push_back(low);
  }
  std::sort(lowest.begin(), lowest.end());
  const float floor = lowest[lowest.size() / 20];
  for (int64_t frame = 0; frame < motion->num_frames(); ++frame)
    motion->trans[static_cast<size_t>(frame * 3 + 2)] -= floor;
}

}  // namespace

// Method: (1) rest alignment. Each SMPL joint s gets a constant A_s with G_smpl(s) = G_src(m(s))
// A_s, chosen so that in the source's rest pose the SMPL bone s -> child(s) points along the source
// bone m(s) -> m(child(s)), with the twist fixed by the body's forward/up axes (the source's body
// frame is read off its rest pose: left = hips, up = spine). (2) Per frame, a swing correction
// turns each SMPL bone onto the source bone between the mapped joints' actual positions (the source
// may have joints between them, e.g. CMU's lowerneck), keeping the twist. (3) The root moves with
// the source root, scaled by the ratio of leg lengths, and y-up becomes z-up. (4) Optionally the
// feet are put on z = 0.
Result<Clip> ImportBvh(const BvhFile& bvh, const std::string& origin,
                       const BvhImportOptions& options, const Skeleton& skeleton) {
  if (bvh.frames < 1) return DataLoss(origin + ": the BVH has no frames");
  JointMap map;
  if (!options.map_path.empty()) {
    MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(options.map_path));
    MP_ASSIGN_OR_RETURN(map, ParseJointMap(text, options.map_path));
  } else {
    MP_ASSIGN_OR_RETURN(map, ChooseJointMap(bvh, origin));
  }
  MP_ASSIGN_OR_RETURN(const JointIndices source_of, MapJoints(bvh, map, origin, skeleton));
  const std::vector<Vec3> rest = RestPositions(bvh);
  MP_ASSIGN_OR_RETURN(const auto align, RestAlignment(bvh, source_of, rest, origin, skeleton));
  MP_ASSIGN_OR_RETURN(const double root_scale,
                      RootScale(source_of, rest, map, options, origin, skeleton));
  Clip clip;
  clip.id = origin.substr(origin.find_last_of('/') + 1);
  clip.source = "bvh:" + clip.id + " map=" + map.name;
  RetargetFrames(bvh, source_of, align, root_scale, skeleton, &clip.motion);
  MP_RETURN_IF_ERROR(CheckResample(clip.motion, options.fps, origin));
  if (options.fps > 0) clip.motion = Resample(clip.motion, options.fps);
  if (options.place_on_floor) PlaceOnFloor(skeleton, &clip.motion);
  MP_RETURN_IF_ERROR(ValidateClip(clip, origin));
  return clip;
}

Result<Clip> ImportBvhFile(const std::string& path, const BvhImportOptions& options) {
  MP_ASSIGN_OR_RETURN(const BvhFile bvh, ReadBvh(path));
  return ImportBvh(bvh, path, options);
}

std::string ExportBvh(const Motion& motion, const Skeleton& skeleton,
                      const BvhExportOptions& options) {
  const double scale = options.units_per_metre;
  std::string out = "HIERARCHY\n";
  char buffer[256];
  // Children lists to write the hierarchy depth-first.
  std::vector<std::vector<int>> children(kNumJoints);
  for (int j = 1; j < kNumJoints; ++j)
    children[static_cast<size_t>(skeleton.parents()[static_cast<size_t>(j)])].push_back(j);
  std::vector<int> order;  // joints in the order their channels appear
  const auto write_joint = [&](const auto& self, int joint, int depth) -> void {
    const std::string indent(static_cast<size_t>(depth), '\t');
    const Vec3 offset =
        joint == 0 ? Vec3{} : scale * skeleton.rest_offsets()[static_cast<size_t>(joint)];
    out += indent + (joint == 0 ? "ROOT " : "JOINT ") +
           skeleton.joint_names()[static_cast<size_t>(joint)] + "\n" + indent + "{\n";
    std::snprintf(buffer, sizeof(buffer), "%s\tOFFSET %.6f %.6f %.6f\n", indent.c_str(), offset.x,
                  offset.y, offset.z);
    out += buffer;
    out +=
        indent + (joint == 0
                      ? "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
                      : "\tCHANNELS 3 Zrotation Yrotation Xrotation\n");
    order.push_back(joint);
    if (children[static_cast<size_t>(joint)].empty()) {
      const Vec3 tip = (0.1 * scale) * LeafDirection(skeleton, joint);  // a 10 cm end marker
      std::snprintf(buffer, sizeof(buffer),
                    "%s\tEnd Site\n%s\t{\n%s\t\tOFFSET %.6f %.6f %.6f\n%s\t}\n", indent.c_str(),
                    indent.c_str(), indent.c_str(), tip.x, tip.y, tip.z, indent.c_str());
      out += buffer;
    }
    for (int child : children[static_cast<size_t>(joint)]) self(self, child, depth + 1);
    out += indent + "}\n";
  };
  write_joint(write_joint, 0, 0);
  std::snprintf(buffer, sizeof(buffer), "MOTION\nFrames: %lld\nFrame Time: %.8f\n",
                static_cast<long long>(motion.num_frames()), 1.0 / motion.fps);
  out += buffer;
  const Mat3 down = Transpose(YUpToZUp());
  constexpr double kRadToDeg = 180.0 / kPi;
  for (int64_t frame = 0; frame < motion.num_frames(); ++frame) {
    const Vec3 root = scale * (down * motion.Translation(frame));
    std::snprintf(buffer, sizeof(buffer), "%.6f %.6f %.6f", root.x, root.y, root.z);
    out += buffer;
    for (int joint : order) {
      Mat3 local = motion.LocalRotation(frame, joint);
      if (joint == 0) local = down * local;
      const auto angles = MatrixToEuler("ZYX", local);
      std::snprintf(buffer, sizeof(buffer), " %.6f %.6f %.6f", angles[0] * kRadToDeg,
                    angles[1] * kRadToDeg, angles[2] * kRadToDeg);
      out += buffer;
    }
    out += "\n";
  }
  return out;
}

Status ExportBvhFile(const std::string& path, const Motion& motion,
                     const BvhExportOptions& options) {
  MP_RETURN_IF_ERROR(ValidateMotion(motion, path));
  return WriteFileAtomic(path, ExportBvh(motion, Skeleton::Smpl22(), options));
}

}  // namespace motionpipe
