// `motionpipe data inspect DIR`: what a corpus holds, read back through the real loaders (clip
// shards, BABEL JSON with the simultaneous-action sweep, MotionFix-style triplets) with the
// plausibility of every clip recomputed.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <string>

#include "motionpipe/base/status.h"

namespace motionpipe::corpus {

struct CorpusReport {
  uint64_t seed = 0;
  int64_t clips = 0, triplets = 0, rejected = 0, frames = 0, segments = 0;
  double fps = 30, min_seconds = 0, mean_seconds = 0, max_seconds = 0;
  std::map<std::string, int64_t> split_clips, split_triplets, actions, edit_kinds;
  std::array<int64_t, 6> part_segments{};  // segments using each body part
  int64_t distinct_labels = 0, distinct_captions = 0;
  // BABEL sweep over the annotations: spans with one action, two, and three or more at once.
  int64_t babel_singles = 0, babel_pairs = 0, babel_multi = 0, babel_sequences = 0;
  // Triplets.
  double mean_source_seconds = 0, mean_target_seconds = 0, mean_edited_fraction = 0;
  // Plausibility over every clip.
  double skate_mean = 0, skate_p95 = 0, skate_max = 0, penetration_max = 0, jerk_mean = 0,
         bone_error_max = 0;
  int64_t joint_limit_violations = 0;
};

Result<CorpusReport> InspectCorpus(const std::string& dir);
std::string FormatCorpusReport(const CorpusReport& report);

}  // namespace motionpipe::corpus
