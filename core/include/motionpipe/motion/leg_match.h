// Legs by motion matching: a post-process that gives a generated motion the legs of the training
// motion whose pelvis path and slow leg posture are nearest, over the generated motion's whole
// length (or, longer than every training motion, in overlapping windows blended where they meet)
// (Clavet 2016, "Motion matching and the road to next-gen animation"; Holden et al. 2020,
// "Learned motion matching"). SINC's generations glide: the pelvis travels while the legs barely
// swing, and a learned clean-up cannot give them a gait, since a denoiser returns the mean of
// what its input leaves open and the mean of a gait's phases is a still leg (docs/EXPERIMENTS.md).
// Matching picks one gait instead. Per frame, heading-free: the pelvis's horizontal velocity in
// its heading frame, its turning speed and its height, and the knees' and ankles' positions
// relative to the pelvis low-passed over `sigma_seconds`; each feature scaled by its spread over
// the database, the path's four and the legs' twelve weighted alike as groups. Only the hips',
// knees', ankles' and feet's local rotations change (and with `match_pelvis` the pelvis's height
// and tilt, its heading and horizontal path kept); the upper body is the motion's own. What the
// model generated is the input; this is not the model: the evaluation reports both.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {

struct LegMatchOptions {
  double sigma_seconds = 0.3;  // the Gaussian low-pass of the leg posture that is matched
  double legs_weight = 1.0;    // the leg posture group's weight (the path's: 1)
  int frame_step = 3;          // frames between the frames compared, and between window starts
  bool match_pelvis = false;   // the pelvis's height and tilt come with the legs
  bool random = false;         // the control: a random window of the same length, not the nearest
  uint64_t seed = 1;           // of the random control
};

// The options as a map, the keys LegMatchOptionsFromJson reads (their one list).
nlohmann::json LegMatchOptionsToJson(const LegMatchOptions& options);
// The options from a map (missing keys keep their defaults; `other_keys` are the caller's own and
// skipped); InvalidArgument naming `origin` and the key for a wrong type, a value out of range or
// an unknown key.
Result<LegMatchOptions> LegMatchOptionsFromJson(const nlohmann::json& params,
                                                const std::string& origin,
                                                const std::vector<std::string>& other_keys = {});

struct LegMatchReport {
  int64_t matched = 0;  // motions given a database window's legs
  int64_t windows = 0;  // windows matched (more than one a motion when it is longer than every
                        // database motion)
  double cost = 0;      // per motion its windows' mean cost per compared frame, summed (0: random)
  double degrees = 0;   // the leg joints' mean change of local rotation, summed per motion
  void Add(const LegMatchReport& other);
  double MeanCost() const { return matched > 0 ? cost / static_cast<double>(matched) : 0.0; }
  double MeanDegrees() const { return matched > 0 ? degrees / static_cast<double>(matched) : 0.0; }
};

// The motions whose windows are matched, and their features. Filled once per stage (Add), then
// matched against; the features' spreads are taken over every motion added before the first Match.
class LegDatabase {
 public:
  LegDatabase(const Skeleton& skeleton, const LegMatchOptions& options);

  // InvalidArgument naming `origin` when the motion is not valid or not at the rate of the first
  // motion added; FailedPrecondition once a motion has been matched. Add(m, o) is
  // Append(Prepare(m, o)).
  Status Add(const Motion& motion, const std::string& origin);

  // One motion's rows of the database, computed apart from it: Prepare reads only the skeleton and
  // the options, so threads may prepare motions at once (the costly part: the features and the
  // leg places) and append them in the order the database is to hold them.
  struct Rows {
    std::string origin;
    double fps = 0;
    int64_t frames = 0;
    std::vector<float> legs, pelvis, height;  // every frame (the members' layouts below)
    std::vector<float> features, places;      // every frame_step-th frame
  };
  // InvalidArgument naming `origin` when the motion is not valid.
  Result<Rows> Prepare(const Motion& motion, const std::string& origin) const;
  // InvalidArgument when the rows are not at the first motion's rate, FailedPrecondition once a
  // motion has been matched.
  Status Append(Rows rows);

  double fps() const { return fps_; }
  int64_t frames() const { return static_cast<int64_t>(height_.size()); }
  int64_t motions() const { return static_cast<int64_t>(length_.size()); }

  // The motion with the legs of its nearest window (the options' `random`: a random window). A
  // motion longer than every database motion is matched in windows of the longest one's length,
  // each starting half a window after the last (the last ending with the motion), each chosen
  // also by how near its knees and ankles come to the last window's over their common frames, and
  // blended into it there (slerp). InvalidArgument when its frame rate is not the database's or it
  // is not a valid motion, FailedPrecondition when the database is empty.
  Result<Motion> Match(const Motion& motion, LegMatchReport* report = nullptr);

 private:
  static constexpr int kPlaces = 12;  // the knees' and ankles' places, 3 each
  struct Choice {
    int64_t motion = -1, start = 0;  // a database motion and its window's first frame
    double cost = std::numeric_limits<double>::infinity();  // per compared frame once chosen
  };
  // The knees' and ankles' places relative to the pelvis, heading removed, at a database frame.
  std::array<float, kPlaces> PlacesAt(int64_t frame) const;
  // The same from a frame's pelvis (3) and legs (24) axis-angles as the database stores them.
  std::array<float, kPlaces> PlacesOf(const float* pelvis, const float* legs) const;
  void Weigh();
  // The nearest window of T frames to `query` (compared frames' features); `joined` holds, for
  // its first compared frames, the last window's leg places that the window is to continue.
  Choice Nearest(const std::vector<float>& query, const std::vector<float>& joined,
                 int64_t T) const;
  Choice Drawn(int64_t T);  // a random window of T frames

  const Skeleton* skeleton_;
  LegMatchOptions options_;
  double fps_ = 0;
  int64_t longest_ = 0;
  // Only what a match reads: per motion its length and first frame, per frame the legs' and the
  // pelvis's local rotations and the pelvis height, and, of every `frame_step`-th frame (the only
  // frames a window starting every frame_step frames compares), the features and the leg places.
  std::vector<int64_t> length_, first_frame_, first_compared_;
  std::vector<float> legs_;      // [frames, 8, 3] axis-angle: per side hip, knee, ankle, toe
  std::vector<float> pelvis_;    // [frames, 3] axis-angle
  std::vector<float> height_;    // [frames] metres
  std::vector<float> features_;  // [compared frames, 16], unscaled
  std::vector<float> places_;    // [compared frames, 12]
  std::vector<float> weights_;   // per feature: group weight / spread^2
  uint64_t draws_ = 0;           // random windows drawn so far
};

// Per-frame features [T, 16] of a motion (the header's list), before the database's scaling.
std::vector<float> LegMatchFeatures(const Skeleton& skeleton, const Motion& motion,
                                    double sigma_seconds);

}  // namespace motionpipe
