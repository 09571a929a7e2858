// motionpipe's clip file: one .npz holding N >= 1 clips, concatenated along frames so that numpy
// users index them with `offsets`. The layout (every stage reads and writes it; README "Clip
// layout"):
//
//   format        <U  ()          "motionpipe.clips/1"
//   ids           <U  (N,)        clip identifiers
//   sources       <U  (N,)        provenance ("cmu:131_01.bvh", "amass:KIT/3/walk_poses.npz", ...)
//   fps           f8  (N,)        frame rate of each clip
//   offsets       i8  (N+1,)      clip i owns frames offsets[i]:offsets[i+1]
//   poses         f4  (F, 22, 3)  local joint rotations, axis-angle, SMPL-22 order, joint 0 global
//   trans         f4  (F, 3)      pelvis translation, metres, z-up
//   joints        f4  (F, 22, 3)  optional: joint positions (forward kinematics), metres, z-up
//   text_offsets  i8  (N+1,)      clip i's descriptions are
//   texts[text_offsets[i]:text_offsets[i+1]] texts         <U  (M,) seg_offsets   i8  (N+1,) clip
//   i's segments are seg_*[seg_offsets[i]:seg_offsets[i+1]] seg_start     i4  (S,)        first
//   frame of the segment (clip-relative) seg_end       i4  (S,)        one past the last frame
//   seg_text      <U  (S,)        the action's label
//   seg_parts     b1  (S, 6)      body parts used, order [global, torso, left arm, right arm, left
//   leg, right leg] seg_action    <U  (S,)        optional: canonical action name (procedural
//   corpus ground truth)
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/npz.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {

inline constexpr char kClipsFormat[] = "motionpipe.clips/1";

struct Segment {
  int32_t start_frame = 0;  // clip-relative, inclusive
  int32_t end_frame = 0;    // exclusive
  std::string text;
  PartSet parts = 0;   // 0 = unknown
  std::string action;  // canonical action name when known (procedural corpus), else empty
};

struct Clip {
  std::string id;
  std::string source;
  Motion motion;
  std::vector<float> joints;  // [T, 22, 3] or empty
  std::vector<std::string> texts;
  std::vector<Segment> segments;
};

// Checks the motion (finite, shapes), joints shape, and segment ranges. Names `origin`.
Status ValidateClip(const Clip& clip, const std::string& origin);

// Builds the npz of the layout above; clips must be valid.
Npz ClipsToNpz(const std::vector<Clip>& clips);
// Parses the layout; every shape, offset and value is checked; DataLoss names `origin`.
Result<std::vector<Clip>> ClipsFromNpz(const Npz& npz, const std::string& origin);

Status WriteClips(const std::string& path, const std::vector<Clip>& clips, bool compress = true);
Result<std::vector<Clip>> ReadClips(const std::string& path);

// Reads any motion file a user may hand us, by content: our clip layout, an AMASS-style npz
// (poses/trans/mocap_framerate), or a BVH (retargeted to SMPL-22 with the built-in joint maps).
// The motion is resampled to `fps` when fps > 0.
Result<std::vector<Clip>> LoadMotionFile(const std::string& path, double fps = 0);

}  // namespace motionpipe
