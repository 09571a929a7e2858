// Editing triplets (source motion, target motion, edit text) in our MotionFix-converted layout.
// MotionFix ships as a joblib pickle; tools/motionfix_convert.py turns it into this npz once:
//
//   format          <U ()          "motionpipe.triplets/1"
//   ids, texts      <U (N,)        triplet id and edit instruction
//   splits          <U (N,)        "train" / "val" / "test"
//   fps             f8 (N,)
//   source_offsets  i8 (N+1,)      triplet i's source frames are source_*[offsets[i]:offsets[i+1]]
//   source_poses    f4 (F, 22, 3)  axis-angle, z-up (MotionFix `rots`)
//   source_trans    f4 (F, 3)
//   source_joints   f4 (F, 22, 3)  optional (MotionFix `joint_positions`)
//   target_*                      the same for the target motions
//   edit_start/end  i4 (N,)        ground-truth edited source frames [start, end); -1 when unknown
//   edit_kind       <U (N,)        optional: the kind of edit (procedural corpus ground truth)
#pragma once

#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/npz.h"
#include "motionpipe/motion/motion.h"

namespace motionpipe {

inline constexpr char kTripletsFormat[] = "motionpipe.triplets/1";

struct Triplet {
  std::string id;
  std::string text;
  std::string split;
  Motion source;
  Motion target;
  std::vector<float> source_joints;  // [T, 22, 3] or empty
  std::vector<float> target_joints;
  int32_t edit_start = -1;
  int32_t edit_end = -1;
  std::string edit_kind;  // empty when unknown
};

Npz TripletsToNpz(const std::vector<Triplet>& triplets);
// Every shape and offset is checked; a triplet whose motions are invalid fails with its id.
Result<std::vector<Triplet>> TripletsFromNpz(const Npz& npz, const std::string& origin);
Status WriteTriplets(const std::string& path, const std::vector<Triplet>& triplets, bool compress = true);
Result<std::vector<Triplet>> ReadTriplets(const std::string& path);

}  // namespace motionpipe
