// The post-processes the pipeline's clean_legs, match_legs and foot_lock stages run on a stage's
// motions, offered on one motion by `motionpipe edit` and `motionpipe generate` (issue 15: the
// demo's best plausibility rows are post-processed, and a user editing or generating one motion
// should be able to ask for the same). Each is a post-process of the model's output, not the
// model: the command prints the plausibility of the raw motion beside the post-processed one.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/motion/motion.h"
#include "plugin_host.h"

namespace motionpipe::cli {

struct PostProcessArgs {
  std::string clean_legs;               // a leg_cleanup checkpoint (the clean_legs stage's)
  std::vector<std::string> match_legs;  // the database: triplet files or directories, motion files
  std::string match_split = "train";    // the triplets of this split (both sides)
  bool foot_lock = false;               // plant the feet (the foot_lock stage's defaults)

  bool any() const { return !clean_legs.empty() || !match_legs.empty() || foot_lock; }
  // What was applied, in order, for a clip's `source` (" + clean_legs + foot_lock"; empty if none).
  std::string Suffix() const;
};

// Declares --clean-legs, --match-legs, --match-split and --foot-lock on `cmd`.
void AddPostProcessOptions(CLI::App* cmd, PostProcessArgs* args);

// The post-processes' inputs checked before the model runs (the --clean-legs checkpoint's kind,
// the --match-legs paths and the --match-split triplets they hold), so that a wrong one is refused
// at once, naming it, and not after an edit or a generation has been computed.
Status CheckPostProcesses(const PostProcessArgs& args);

// The motion cleaned (a leg_cleanup checkpoint), given matched legs (motion matching against the
// database, brought to the motion's rate), then planted, in that order, each when asked for. Prints
// one line per step that ran (what it changed) and the plausibility of the raw and the final motion
// (foot skate as the evaluation counts it, GMD's skating ratio, frames floating, jerk). Errors name
// the file or checkpoint at fault.
Result<Motion> ApplyPostProcesses(const PostProcessArgs& args, const worker::PluginHost& host,
                                  const Motion& raw);

}  // namespace motionpipe::cli
