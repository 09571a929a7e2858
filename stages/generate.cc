// `generate`: generates the test split's action texts (two-action pairs by default) with a
// text-to-motion checkpoint, at each ground-truth motion's length, sharded.
#include <algorithm>
#include <filesystem>

#include "inputs.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/random.h"
#include "motionpipe/formats/clip.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

// params: model (the train stage), split (test), spans (pairs | singles | all), limit, compositing
// (single-action checkpoints: the GPT-compositing baseline), samples (generations per text, 1),
// reconstruct (true: each span's ground truth through the model's motion encoder and decoder
// instead of its text: what the decoder can give back), singles (the spans: an input's name or a
// path pattern such as "out/demo-1/singles"; default the input that has them).
class GenerateStage : public StageExecutor {
 public:
  // `shards` tasks (default 2) over the test spans.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    if (!plan.shards_set) plan.shards = 2;
    plan.reduce = false;
    if (plan.inputs.empty() && !(plan.params.contains("model") && plan.params.contains("singles")))
      errors->push_back(path +
                        ": needs inputs: the train stage of the model and a `singles` stage");
    CheckInputParams(plan, path, {"model", "singles"}, errors);
    const auto& p = plan.params;
    if (p.contains("spans") && p["spans"] != "pairs" && p["spans"] != "singles" &&
        p["spans"] != "all") {
      errors->push_back(path + ".params.spans: pairs, singles or all");
    }
    LongLease(plan);
  }
  explicit GenerateStage(const PluginHost* plugins) : plugins_(plugins) {}
  std::string Description() const override {
    return "generates the test split's action texts with a text-to-motion checkpoint, sharded";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    if (!plugins_) return TaskReport::Error("generate: this worker has no plugin host");
    fs::create_directories(ctx.output_dir());
    json options = p.value("options", json::object());
    if (p.value("compositing", false)) options["compositing"] = true;
    const bool reconstruct = p.value("reconstruct", false);
    if (reconstruct) options["reconstruct"] = true;
    std::string checkpoint;
    auto generator = OpenModel(ctx, *plugins_, options, &checkpoint);
    if (!generator.ok()) return TaskReport::BadInput("generate: " + generator.status().message());
    auto table = InputSpans(ctx, p.value("singles", std::string()));
    if (!table.ok()) return TaskReport::BadInput("generate: " + table.status().message());
    const auto spans = SelectSpans(*table, p);
    if (spans.empty())
      return TaskReport::BadInput("generate: no spans of that split and kind in the inputs");
    const int samples = std::max(1, p.value("samples", 1));
    std::vector<Clip> clips;
    const auto started = std::chrono::steady_clock::now();
    for (size_t k = static_cast<size_t>(ctx.spec.index()); k < spans.size();
         k += static_cast<size_t>(std::max(1, ctx.spec.count()))) {
      if (ctx.cancelled()) return TaskReport::Error("cancelled");
      const int64_t i = spans[k];
      const Motion truth = reconstruct ? table->MotionOf(i) : Motion{};  // once per span
      for (int sample = 0; sample < samples; ++sample) {
        plugin::GenerateRequest r;
        r.texts = {table->text_a[static_cast<size_t>(i)]};
        if (!table->single(i)) r.texts.push_back(table->text_b[static_cast<size_t>(i)]);
        r.frames = table->frames(i);
        r.fps = table->fps[static_cast<size_t>(i)];
        r.seed = MixSeed(ctx.spec.seed(), static_cast<uint64_t>(i * 1000 + sample));
        if (reconstruct) r.source = &truth;
        auto motion = (*generator)->Generate(r);
        if (!motion.ok()) return TaskReport::Error(motion.status().message());
        Clip clip;
        clip.id =
            table->ids[static_cast<size_t>(i)] + (samples > 1 ? "#" + std::to_string(sample) : "");
        clip.source = "generate:" + (*generator)->Name();
        clip.motion = std::move(*motion);
        clip.texts = {SpanText(*table, i)};
        clips.push_back(std::move(clip));
      }
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    if (!clips.empty()) {
      if (Status st = WriteClips(ctx.output_dir() + "/generated.npz", clips); !st.ok())
        return TaskReport::Error(st.message());
    }
    const json summary = {
        {"model", (*generator)->Name()},
        {"checkpoint", checkpoint},
        {"generated", clips.size()},
        {"seconds", seconds},
        {"motions_per_second", static_cast<double>(clips.size()) / std::max(seconds, 1e-9)}};
    if (Status st = WriteFileAtomic(ctx.output_dir() + "/generate.json", summary.dump(1) + "\n");
        !st.ok())
      return TaskReport::Error(st.message());
    TaskReport out = TaskReport::Ok();
    out.metrics["generated"] = static_cast<double>(clips.size());
    return out;
  }

 private:
  const PluginHost* plugins_;
};

}  // namespace

MP_STAGE_KIND("generate", GenerateStage);

}  // namespace motionpipe::stages
