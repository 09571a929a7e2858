// BABEL annotations (REFERENCE.md 4.4): a JSON object of sequences, each with `seq_ann.labels[]`
// and `frame_ann.labels[]` (frame_ann may be null), labels carrying proc_label, raw_label, act_cat,
// start_t, end_t (seconds). From them: real single actions and simultaneous actions, found by a
// sweep over segment boundaries.
#pragma once

#include <string>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe {

struct BabelLabel {
  std::string proc_label;
  std::string raw_label;
  std::vector<std::string> act_cat;
  double start_t = 0;
  double end_t = 0;
};

struct BabelSequence {
  std::string sid;           // babel_sid (or the object key)
  std::string feat_p;        // path of the AMASS npz, relative to the AMASS root
  double duration = 0;       // seconds
  bool frame_level = false;  // labels come from frame_ann (else seq_ann spans the whole sequence)
  std::vector<BabelLabel> labels;
};

// Parses the JSON text. DataLoss names `origin`, the sequence key and the bad field.
Result<std::vector<BabelSequence>> ParseBabel(const std::string& json_text,
                                              const std::string& origin);
Result<std::vector<BabelSequence>> ReadBabel(const std::string& path);

// t-pose, a-pose, transition and their spellings ("t pose", "tpose", "transition", ...).
bool IsExcludedBabelLabel(const std::string& label);

// A span of frames over which the set of (non-excluded) actions is constant.
struct ActionSpan {
  int start_frame = 0;              // inclusive
  int end_frame = 0;                // exclusive
  std::vector<std::string> labels;  // proc_labels active over the whole span, distinct, sorted
};

struct BabelSpanOptions {
  double fps = 30;
  int min_frames = 15;  // SINC: clips of 15..600 frames
  int max_frames = 600;
  int max_actions = 4;  // spans with more simultaneous actions are dropped
};

// The sweep: sorts start/end events of the sequence's labels, and emits each maximal span with a
// constant non-empty set of active actions whose length is within [min_frames, max_frames].
std::vector<ActionSpan> SweepActionSpans(const BabelSequence& sequence,
                                         const BabelSpanOptions& options);

}  // namespace motionpipe
