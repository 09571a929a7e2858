// What the post-process stage kinds (foot_lock, clean_legs, match_legs) share: an edit or generate
// stage's motions read, each changed by the post-process, and written in that stage's layout
// (edited.npz + edits.json, generated.npz + generate.json), so that eval_edit and eval_generate
// score them as they score the raw ones. The summary keeps the input's model and checkpoint, marked
// with the post-process (what the report names the row by).
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "motionpipe/base/status.h"
#include "motionpipe/motion/motion.h"
#include "stage.h"

namespace motionpipe::stages {

struct PostProcess {
  std::string kind;     // the stage kind, for messages ("foot_lock")
  std::string label;    // appended to the input's model name ("foot lock")
  std::string key;      // the summary's entry for `summarise`
  std::string motions;  // params.motions: the input stage or a path pattern ("": every input)
  std::function<Result<Motion>(const Motion&)> change;
  // Called after each layout's motions (their count) for the summary's entry; may reset totals.
  std::function<json(int64_t motions)> summarise;
};

// Ok with metrics["motions"], BadInput when the inputs hold no motions or a file is unreadable.
TaskReport PostProcessMotions(TaskContext& ctx, const PostProcess& post);

}  // namespace motionpipe::stages
