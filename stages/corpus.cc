// `corpus`: the embedded procedural corpus, sharded.
#include "motionpipe/corpus/corpus.h"

#include "stage.h"

namespace motionpipe::stages {

namespace {

// params.manner_words: the share of clip texts that state their action's manner (tempo,
// repetitions, size; corpus::CorpusOptions::manner_words); 0 when absent.
// params.edit_kinds: the kinds of edit the triplets make (a list of corpus::EditKindName names);
// every kind when absent.
Result<corpus::EditKindSet> EditKinds(const nlohmann::json& params) {
  const auto it = params.find("edit_kinds");
  if (it == params.end()) return corpus::kEveryEditKind;
  if (!it->is_array() || it->empty())
    return InvalidArgument("a non-empty list of edit kinds, e.g. [side, amplitude]");
  std::vector<std::string> names;
  for (const auto& name : *it) {
    if (!name.is_string()) return InvalidArgument("edit kinds are names, got " + name.dump());
    names.push_back(name.get<std::string>());
  }
  return corpus::ParseEditKinds(names);
}

// The procedural corpus: each shard task generates its clips and triplets, the reduce task merges
// them into one corpus directory (byte-identical to `motionpipe data synth-corpus`).
class CorpusStage : public StageExecutor {
 public:
  // Shards of shard_size clips (and triplets), then a reduce task that merges them into one corpus
  // directory with its annotations and manifest.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    const int clips = IntParam(plan.params, "clips", 1000, 1, path, errors);
    const int triplets = IntParam(plan.params, "triplets", clips, 0, path, errors);
    const int shard_size = IntParam(plan.params, "shard_size", 500, 1, path, errors);
    if (const auto kinds = EditKinds(plan.params); !kinds.ok())
      errors->push_back(path + ".params.edit_kinds: " + kinds.status().message());
    if (const auto it = plan.params.find("manner_words"); it != plan.params.end()) {
      const Status s = it->is_number()
                           ? corpus::CheckMannerWords(it->get<double>())
                           : InvalidArgument("a share in [0, 1] of texts, got " + it->dump());
      if (!s.ok()) errors->push_back(path + ".params.manner_words: " + s.message());
    }
    plan.shards = std::max(1, (std::max(clips, triplets) + shard_size - 1) / shard_size);
    plan.reduce = true;
  }
  std::string Description() const override {
    return "generates the procedural motion corpus (sharded)";
  }
  TaskReport Run(TaskContext& ctx) override {
    corpus::CorpusOptions options;
    const auto& p = ctx.params;
    options.seed = p.value("seed", ctx.spec.seed());
    options.clips = p.value("clips", int64_t{1000});
    options.triplets = p.value("triplets", options.clips);
    options.shard_size = p.value("shard_size", 500);
    options.fps = p.value("fps", 30.0);
    options.write_amass = p.value("amass", true);
    options.triplet_joints = p.value("triplet_joints", true);
    options.script.min_seconds = p.value("min_seconds", options.script.min_seconds);
    options.script.max_seconds = p.value("max_seconds", options.script.max_seconds);
    auto kinds = EditKinds(p);
    if (!kinds.ok()) return TaskReport::FromStatus(kinds.status());
    options.edit_kinds = *kinds;
    options.manner_words = p.value("manner_words", 0.0);
    options.threads = ctx.threads;
    options.out_dir = ctx.output_dir();
    if (ctx.spec.reduce()) {
      const std::vector<std::string> shards(ctx.spec.shard_dirs().begin(),
                                            ctx.spec.shard_dirs().end());
      auto summary = corpus::FinalizeCorpus(options, shards);
      if (!summary.ok()) return TaskReport::Error(summary.status().message());
      TaskReport report;
      report.metrics["clips"] = static_cast<double>(summary->clips);
      report.metrics["triplets"] = static_cast<double>(summary->triplets);
      return report;
    }
    if (const Status s = corpus::GenerateCorpusShard(options, ctx.spec.index(), ctx.output_dir());
        !s.ok()) {
      return TaskReport::FromStatus(s);
    }
    return TaskReport::Ok();
  }
};

}  // namespace

MP_STAGE_KIND("corpus", CorpusStage);

}  // namespace motionpipe::stages
