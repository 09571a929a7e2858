// `foot_lock`: plants the feet of an edit or generate stage's motions (motion/foot_lock.h) and
// writes them in that stage's layout (edited.npz + edits.json, generated.npz + generate.json), so
// that eval_edit and eval_generate score them as they score the raw ones. A post-process of the
// model's output, not the model: evaluate both and report them side by side.
//
// params: motions (the edit or generate stage, or a path pattern such as "out/demo-1/edit_mdt";
//   default: every input), contact_height (m, 0.05), max_speed (m/s, 1.0), min_frames (2),
//   blend_seconds (0.1)
#include "motionpipe/motion/foot_lock.h"

#include <filesystem>

#include "inputs.h"
#include "motionpipe/base/file.h"
#include "motionpipe/formats/clip.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

// The clip files foot_lock reads and writes, each with its stage's summary.
struct Layout {
  const char* clips;
  const char* summary;
};
constexpr Layout kLayouts[] = {{"edited.npz", "edits.json"}, {"generated.npz", "generate.json"}};

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
    fs::create_directories(ctx.output_dir());
    const Skeleton& skeleton = Skeleton::Smpl22();
    int64_t motions = 0;
    FootLockReport all;
    for (const Layout& layout : kLayouts) {
      FootLockReport total;
      std::vector<Clip> clips;
      json summary;
      for (const std::string& dir : StageDirs(ctx, p.value("motions", std::string()))) {
        if (!fs::exists(dir + "/" + layout.clips)) continue;
        auto read = ReadClips(dir + "/" + layout.clips);
        if (!read.ok()) return TaskReport::BadInput("foot_lock: " + read.status().message());
        for (Clip& clip : *read) {
          if (ctx.cancelled()) return TaskReport::Error("cancelled");
          FootLockReport one;
          clip.motion = LockFeet(skeleton, clip.motion, options, &one);
          total.Add(one);
          clips.push_back(std::move(clip));
        }
        if (summary.is_null()) {
          auto text = ReadFile(dir + "/" + layout.summary);
          if (text.ok()) summary = json::parse(*text, nullptr, false);
        }
      }
      if (clips.empty()) continue;
      motions += static_cast<int64_t>(clips.size());
      all.Add(total);
      if (Status s = WriteClips(ctx.output_dir() + "/" + layout.clips, clips); !s.ok())
        return TaskReport::Error(s.message());
      // The input's model and checkpoint (what eval_edit/eval_generate name the row by), marked.
      const json input = summary.is_object() ? summary : json::object();
      summary = {{"model", input.value("model", std::string("motions")) + " + foot lock"},
                 {"checkpoint", input.value("checkpoint", std::string())},
                 {"input", input}};
      summary["foot_lock"] = {{"motions", clips.size()},
                              {"held_foot_frames", total.held},
                              {"runs", total.runs},
                              {"unreached_ankle_frames", total.unreached},
                              {"mean_shift_m", total.MeanShift()},
                              {"max_reach_error_m", total.max_reach_error},
                              {"options", FootLockOptionsToJson(options)}};
      if (Status s =
              WriteFileAtomic(ctx.output_dir() + "/" + layout.summary, summary.dump(1) + "\n");
          !s.ok())
        return TaskReport::Error(s.message());
    }
    if (motions == 0)
      return TaskReport::BadInput(
          "foot_lock: no edited.npz or generated.npz in the inputs (an edit or generate stage)");
    TaskReport out = TaskReport::Ok();
    out.metrics["motions"] = static_cast<double>(motions);
    out.metrics["held_foot_frames"] = static_cast<double>(all.held);
    out.metrics["unreached_ankle_frames"] = static_cast<double>(all.unreached);
    return out;
  }
};

}  // namespace

MP_STAGE_KIND("foot_lock", FootLockStage);

}  // namespace motionpipe::stages
