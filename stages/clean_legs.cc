// `clean_legs`: the legs of an edit or generate stage's motions cleaned by a leg_cleanup checkpoint
// (plugins/leg_cleanup: temporal convolutions trained on the corpus's training motions to give
// back clean hip, knee and ankle rotations, and with `height` the pelvis height, from corrupted
// ones), written in that stage's layout (post_process.h) so that eval_edit and eval_generate score
// them as rows of their own. A post-process and the corpus's prior, not a model of either paper:
// it makes real mocap slide more (docs/EXPERIMENTS.md "A learned clean-up of the legs"). Chain a
// foot_lock stage after it to plant the cleaned feet.
//
// params: model (the train stage holding the leg_cleanup checkpoint, or a path pattern; default:
//   the input that has one), motions (the edit or generate stage, or a path pattern; default:
//   every input)
#include "inputs.h"
#include "post_process.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

class CleanLegsStage : public StageExecutor {
 public:
  explicit CleanLegsStage(const PluginHost* plugins) : plugins_(plugins) {}

  // One task: the motions of every task of the input stage.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    if (plan.inputs.empty() && !(plan.params.contains("motions") && plan.params.contains("model")))
      errors->push_back(path +
                        ": needs inputs (a train stage of a leg_cleanup model and an edit or "
                        "generate stage) or params.model and params.motions");
    CheckInputParams(plan, path, {"model", "motions"}, errors);
  }
  std::string Description() const override {
    return "cleans the legs of an edit or generate stage's motions with a leg_cleanup checkpoint "
           "(a post-process)";
  }

  TaskReport Run(TaskContext& ctx) override {
    if (!plugins_) return TaskReport::Error("clean_legs: this worker has no plugin host");
    std::string checkpoint;
    auto generator = OpenModel(ctx, *plugins_, json::object(), &checkpoint, "leg_cleanup");
    if (!generator.ok()) return TaskReport::BadInput("clean_legs: " + generator.status().message());
    PostProcess post;
    post.kind = "clean_legs";
    post.label = "leg clean-up";
    post.key = "clean_legs";
    post.motions = ctx.params.value("motions", std::string());
    post.change = [&](const Motion& motion) {
      plugin::GenerateRequest request;
      request.source = &motion;
      return (*generator)->Generate(request);
    };
    post.summarise = [&](int64_t motions) {
      return json{{"motions", motions}, {"checkpoint", checkpoint}};
    };
    return PostProcessMotions(ctx, post);
  }

 private:
  const PluginHost* plugins_;
};

}  // namespace

MP_STAGE_KIND("clean_legs", CleanLegsStage);

}  // namespace motionpipe::stages
