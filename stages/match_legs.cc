// `match_legs`: the legs of an edit or generate stage's motions taken from the nearest window of a
// corpus's training motions (motion/leg_match.h: motion matching on the pelvis path and the slow
// leg posture), written in that stage's layout (post_process.h) so that eval_edit and
// eval_generate score them as rows of their own (a motion longer than every database motion in
// overlapping windows, blended). A post-process and the corpus's motions, not a
// model of either paper: it gives SINC's gliding bodies a gait that the learned clean-up cannot
// (docs/EXPERIMENTS.md "Legs by motion matching"). Chain a foot_lock stage after it to plant the
// matched feet. With `random: true` it is the control: a random window of the same length.
//
// params: motions (the edit or generate stage, or a path pattern; default: every input that is
//   not the database), database (the stage with triplet files, or a path pattern: both sides of
//   its `split` triplets are the database), split (train), limit (triplets of the split, 0: all),
//   and the matching options: sigma_seconds (0.3), legs_weight (1), frame_step (3), match_pelvis
//   (false), random (false), seed (1)
#include "inputs.h"
#include "motionpipe/motion/leg_match.h"
#include "post_process.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

const std::vector<std::string> kOwnKeys = {"motions", "database", "split", "limit"};

class MatchLegsStage : public StageExecutor {
 public:
  // One task: the motions of every task of the input stage.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    if (!plan.params.contains("database"))
      errors->push_back(path + ".params.database: needed (the corpus stage whose triplets' " +
                        "training motions give the legs)");
    if (plan.inputs.empty() && !plan.params.contains("motions"))
      errors->push_back(path + ": needs an input (an edit or generate stage) or params.motions");
    CheckInputParams(plan, path, {"motions", "database"}, errors);
    if (auto options = LegMatchOptionsFromJson(plan.params, path + ".params", kOwnKeys);
        !options.ok())
      errors->push_back(options.status().message());
  }
  std::string Description() const override {
    return "gives an edit or generate stage's motions the legs of the nearest training motion "
           "(motion matching, a post-process)";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    auto parsed = LegMatchOptionsFromJson(p, "match_legs.params", kOwnKeys);
    if (!parsed.ok()) return TaskReport::BadInput(parsed.status().message());
    const LegMatchOptions& options = *parsed;
    const std::string database_stage = p.value("database", std::string());
    const std::string split = p.value("split", std::string("train"));
    const int64_t limit = p.value("limit", int64_t{0});
    LegDatabase database(Skeleton::Smpl22(), options);
    const auto added = AddTripletSides(
        TripletFiles(ctx, database_stage), split, limit,
        [](const Motion& motion) { return motion; }, &database);
    if (!added.ok()) return TaskReport::BadInput("match_legs: " + added.status().message());
    const int64_t triplets = *added;
    if (triplets == 0)
      return TaskReport::BadInput("match_legs: no triplets of split '" + split + "' in " +
                                  (database_stage.empty() ? "the inputs" : database_stage));
    LegMatchReport layout, all;
    PostProcess post;
    post.kind = "match_legs";
    post.label = options.random ? "random legs" : "matched legs";
    post.key = "match_legs";
    post.motions = p.value("motions", std::string());
    post.change = [&](const Motion& motion) { return database.Match(motion, &layout); };
    post.summarise = [&](int64_t motions) {
      const json entry = {{"motions", motions},
                          {"matched", layout.matched},
                          {"windows", layout.windows},
                          {"mean_cost", layout.MeanCost()},
                          {"mean_leg_change_degrees", layout.MeanDegrees()},
                          {"database_triplets", triplets},
                          {"database_frames", database.frames()},
                          {"options", LegMatchOptionsToJson(options)}};
      all.Add(layout);
      layout = LegMatchReport{};
      return entry;
    };
    TaskReport out = PostProcessMotions(ctx, post);
    if (out.outcome == worker::Outcome::kOk) {
      out.metrics["matched"] = static_cast<double>(all.matched);
      out.metrics["windows"] = static_cast<double>(all.windows);
      out.metrics["mean_leg_change_degrees"] = all.MeanDegrees();
    }
    return out;
  }
};

}  // namespace

MP_STAGE_KIND("match_legs", MatchLegsStage);

}  // namespace motionpipe::stages
