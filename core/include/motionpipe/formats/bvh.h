// BVH motion capture files: parsing, import onto SMPL-22 (retargeting through a joint-name map,
// rest-pose alignment, unit scale, y-up -> z-up) and export of SMPL-22 motions (so Blender or any
// DCC tool opens our output).
#pragma once

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/math/rotation.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {

enum class BvhChannel { kXpos, kYpos, kZpos, kXrot, kYrot, kZrot };

struct BvhJoint {
  std::string name;
  int parent = -1;
  Vec3 offset;                       // file units, parent frame
  std::vector<BvhChannel> channels;  // in file order
  int first_channel = 0;             // column of channels[0] in a frame row
  std::string rotation_order;        // e.g. "ZYX" (order of the rotation channels), empty if none
  bool has_end_site = false;
  Vec3 end_site;
};

struct BvhFile {
  std::vector<BvhJoint> joints;  // parents precede children
  int64_t frames = 0;
  double frame_time = 0;  // seconds
  int channels_per_frame = 0;
  std::vector<float> values;  // [frames, channels_per_frame], rotations in degrees

  int JointIndex(const std::string& name) const;
};

// Parses a BVH text. DataLoss names `origin`, the line, and what is wrong (broken hierarchy,
// channel count, missing or non-numeric motion values, truncated frames).
Result<BvhFile> ParseBvh(std::string_view text, const std::string& origin);
Result<BvhFile> ReadBvh(const std::string& path);

// SMPL-22 joint -> source joint name, in SMPL joint order.
struct JointMap {
  std::string name;
  std::array<std::string, kNumJoints> source;
  double unit_scale = 0;  // metres per file unit when known for this rig (CMU: 0.056444), else 0
};

// Built-in maps: "cmu" (cgspeed conversion of the CMU database), "smpl22" (our own export),
// "mixamo".
const std::vector<JointMap>& BuiltinJointMaps();
// A map file: one "smpl_joint: source_joint" per line, '#' comments, optional "unit_scale: 0.01".
// All 22 SMPL joints must be listed; the error names those that are not.
Result<JointMap> ParseJointMap(const std::string& text, const std::string& origin);
// Source joint names match when equal, or equal after stripping a "namespace:" prefix.
// Returns the first built-in map that covers the file, else an error listing, for the closest
// map, the SMPL joints it cannot find.
Result<JointMap> ChooseJointMap(const BvhFile& bvh, const std::string& origin);

struct BvhImportOptions {
  double fps = 30;             // resample to this rate (0 keeps the file's)
  std::string map_path;        // a joint-map file; empty = choose a built-in map
  bool place_on_floor = true;  // shift vertically so the feet touch z = 0
  // Root trajectory scaled by SMPL leg length / source leg length (stride follows the body, the
  // usual retargeting choice). When false the trajectory keeps its true size in metres, using
  // `unit_scale` (metres per file unit) or the map's known scale.
  bool scale_root_to_leg = true;
  double unit_scale = 0;
};

// Retargets to SMPL-22 (see bvh.cc for the method). The clip's source names the file and map.
Result<Clip> ImportBvh(const BvhFile& bvh, const std::string& origin,
                       const BvhImportOptions& options,
                       const Skeleton& skeleton = Skeleton::Smpl22());
Result<Clip> ImportBvhFile(const std::string& path, const BvhImportOptions& options);

struct BvhExportOptions {
  double units_per_metre =
      100;  // file units per metre: centimetres (import in Blender at scale 0.01)
};

// SMPL-22 hierarchy with our rest offsets, y-up, root with 6 channels and every joint ZYX.
std::string ExportBvh(const Motion& motion, const Skeleton& skeleton = Skeleton::Smpl22(),
                      const BvhExportOptions& options = {});
Status ExportBvhFile(const std::string& path, const Motion& motion,
                     const BvhExportOptions& options = {});

// Source joints' global rotations and positions (file units, y-up) for one frame; for tests and
// tools that compare retargeted motion with its source.
void BvhForwardKinematics(const BvhFile& bvh, int64_t frame, std::vector<Mat3>* global,
                          std::vector<Vec3>* positions);

}  // namespace motionpipe
