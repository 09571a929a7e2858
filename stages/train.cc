// `train`: planned here, run by the train plugin (plugins/train: it links LibTorch, which the
// engine does not; the C ABI has no planning entry). One task per rank: world_size > 1 makes a gang
// that starts together on distinct workers and restarts together from the last checkpoint when a
// rank fails. params.model names the model plugin.
#include <algorithm>

#include "stage.h"

namespace motionpipe::stages {

namespace {

void PlanTrainStage(StagePlan& plan, const std::string& path, std::vector<std::string>* errors) {
  plan.shards = std::max(1, plan.world_size);
  plan.reduce = false;
  if (!plan.params.contains("model") || !plan.params["model"].is_string())
    errors->push_back(path +
                      ".params.model: the model plugin's name is required (e.g. temos_sinc)");
  LongLease(plan);
}

}  // namespace

MP_STAGE_PLANNER("train", PlanTrainStage);

}  // namespace motionpipe::stages
