// `foot_lock`: plants the feet of an edit or generate stage's motions (motion/foot_lock.h) and
// writes them in that stage's layout (post_process.h), so that eval_edit and eval_generate score
// them as they score the raw ones. A post-process of the model's output, not the model: evaluate
// both and report them side by side.
//
// params: motions (the edit or generate stage, or a path pattern such as "out/demo-1/edit_mdt";
//   default: every input), contact_height (m, 0.05), max_speed (m/s, 1.0), min_frames (2),
//   blend_seconds (0.1)
#include "motionpipe/motion/foot_lock.h"

#include "inputs.h"
#include "post_process.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

class FootLockStage : public StageExecutor {
 public:
  // One task: the motions of every task of the input stage.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    if (plan.inputs.empty() && !plan.params.contains("motions"))
      errors->push_back(path + ": needs an input (an edit or generate stage) or params.motions");
    CheckInputParams(plan, path, {"motions"}, errors);
    if (auto options = FootLockOptionsFromJson(plan.params, path + ".params", {"motions"});
        !options.ok())
      errors->push_back(options.status().message());
  }
  std::string Description() const override {
    return "plants the feet of an edit or generate stage's motions (a post-process)";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    auto parsed = FootLockOptionsFromJson(p, "foot_lock.params", {"motions"});
    if (!parsed.ok()) return TaskReport::BadInput(parsed.status().message());
    const FootLockOptions& options = *parsed;
    const Skeleton& skeleton = Skeleton::Smpl22();
    FootLockReport layout, all;  // one layout's totals, every motion's
    PostProcess post;
    post.kind = "foot_lock";
    post.label = "foot lock";
    post.key = "foot_lock";
    post.motions = p.value("motions", std::string());
    post.change = [&](const Motion& motion) -> Result<Motion> {
      FootLockReport one;
      Motion locked = LockFeet(skeleton, motion, options, &one);
      layout.Add(one);
      return locked;
    };
    post.summarise = [&](int64_t motions) {
      const json entry = {{"motions", motions},
                          {"held_foot_frames", layout.held},
                          {"runs", layout.runs},
                          {"unreached_ankle_frames", layout.unreached},
                          {"mean_shift_m", layout.MeanShift()},
                          {"max_reach_error_m", layout.max_reach_error},
                          {"max_pelvis_lowered_m", layout.max_lowered},
                          {"options", FootLockOptionsToJson(options)}};
      all.Add(layout);
      layout = FootLockReport{};
      return entry;
    };
    TaskReport out = PostProcessMotions(ctx, post);
    if (out.outcome == worker::Outcome::kOk) {
      out.metrics["held_foot_frames"] = static_cast<double>(all.held);
      out.metrics["unreached_ankle_frames"] = static_cast<double>(all.unreached);
    }
    return out;
  }
};

}  // namespace

MP_STAGE_KIND("foot_lock", FootLockStage);

}  // namespace motionpipe::stages
