// `edit`: edits the test split's triplets with an editing checkpoint (SimMotionEdit's MDT and its
// baselines, through the generator interface), sharded over workers, writing the edited motions as
// a clip file per task.
//
// params: model (the input stage holding the checkpoint; default: the input that has one),
//   triplets (an input stage or a path pattern; default: every input), split (test), limit (0 =
//   all), batch (8), sampler (ddpm | ddim), steps (DDIM steps), seed, body_parts (MDM-BP), options
//   (merged into the generator's configuration), length (target: each edit has its target's number
//   of frames, as the authors' evaluation generates at length_target; source: the source's; MDM-BP
//   keeps the source's timing either way)
#include <algorithm>
#include <filesystem>

#include "inputs.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/random.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

// The triplets of a split that one edit task takes: every count-th of the split (in file and row
// order, after `limit`), each with its place in the split (its sampling seed, whatever the
// batching), longest source first so that a batch is padded little.
struct TaskTriplets {
  struct Item {
    size_t file;
    int64_t row;
  };
  std::vector<TripletColumns> files;
  std::vector<Item> items;
  std::vector<uint64_t> place;
};

Result<TaskTriplets> TasksTriplets(const TaskContext& ctx, const std::string& stage,
                                   const std::string& split, int64_t limit) {
  TaskTriplets out;
  std::vector<TaskTriplets::Item> all;
  for (const std::string& path : TripletFiles(ctx, stage)) {
    MP_ASSIGN_OR_RETURN(auto columns, ReadTripletColumns(path, {0, -1, true, false}));
    for (int64_t r = 0; r < columns.rows; ++r) {
      if (columns.splits[static_cast<size_t>(r)] == split) all.push_back({out.files.size(), r});
    }
    out.files.push_back(std::move(columns));
  }
  if (all.empty())
    return InvalidArgument("edit: no triplets of split '" + split + "' in the inputs");
  if (limit > 0 && static_cast<int64_t>(all.size()) > limit) all.resize(static_cast<size_t>(limit));
  std::vector<size_t> mine;
  for (size_t k = static_cast<size_t>(ctx.spec.index()); k < all.size();
       k += static_cast<size_t>(std::max(1, ctx.spec.count()))) {
    mine.push_back(k);
  }
  const auto length = [&](size_t k) {
    const auto& o = out.files[all[k].file].source.offsets;
    return o[all[k].row + 1] - o[all[k].row];
  };
  std::stable_sort(mine.begin(), mine.end(),
                   [&](size_t a, size_t b) { return length(a) > length(b); });
  for (size_t k : mine) out.items.push_back(all[k]), out.place.push_back(k);
  return out;
}

class EditStage : public StageExecutor {
 public:
  // `shards` tasks (default 2), each every count-th triplet of the test split.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    if (!plan.shards_set) plan.shards = 2;
    plan.reduce = false;
    if (plan.inputs.empty() && !(plan.params.contains("model") && plan.params.contains("triplets")))
      errors->push_back(path +
                        ": needs inputs: the train stage of the editor and a stage with triplets");
    CheckInputParams(plan, path, {"model", "triplets"}, errors);
    const auto& p = plan.params;
    if (p.contains("sampler") && p["sampler"] != "ddpm" && p["sampler"] != "ddim")
      errors->push_back(path + ".params.sampler: ddpm or ddim");
    if (p.contains("length") && p["length"] != "target" && p["length"] != "source")
      errors->push_back(path + ".params.length: target or source");
    LongLease(plan);
  }
  explicit EditStage(const PluginHost* plugins) : plugins_(plugins) {}
  std::string Description() const override {
    return "edits the test triplets with an editing checkpoint, sharded";
  }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    if (!plugins_) return TaskReport::Error("edit: this worker has no plugin host");
    fs::create_directories(ctx.output_dir());
    json options = p.value("options", json::object());
    if (p.value("body_parts", false)) options["body_parts"] = true;
    std::string checkpoint;
    auto generator = OpenModel(ctx, *plugins_, options, &checkpoint);
    if (!generator.ok()) return TaskReport::BadInput("edit: " + generator.status().message());
    const std::string split = p.value("split", std::string("test"));
    const int64_t limit = p.value("limit", int64_t{0});
    const int batch_size = std::max(1, p.value("batch", 8));
    const bool target_length = p.value("length", std::string("target")) == "target";
    auto triplets = TasksTriplets(ctx, p.value("triplets", std::string()), split, limit);
    if (!triplets.ok()) return TaskReport::BadInput(triplets.status().message());
    const std::vector<TripletColumns>& files = triplets->files;
    const std::vector<TaskTriplets::Item>& mine = triplets->items;
    const std::vector<uint64_t>& place = triplets->place;
    std::vector<Clip> clips;
    const auto started = std::chrono::steady_clock::now();
    for (size_t at = 0; at < mine.size(); at += static_cast<size_t>(batch_size)) {
      if (ctx.cancelled()) return TaskReport::Error("cancelled");
      const size_t end = std::min(mine.size(), at + static_cast<size_t>(batch_size));
      std::vector<Motion> sources;
      for (size_t k = at; k < end; ++k)
        sources.push_back(SideMotion(files[mine[k].file], mine[k].row, true));
      std::vector<plugin::GenerateRequest> requests;
      for (size_t k = at; k < end; ++k) {
        const TripletColumns& c = files[mine[k].file];
        plugin::GenerateRequest r;
        r.texts = {c.texts[static_cast<size_t>(mine[k].row)]};
        r.source = &sources[k - at];
        r.seed = MixSeed(ctx.spec.seed(), place[k]);
        r.sampler = p.value("sampler", std::string("ddpm"));
        r.steps = p.value("steps", 0);
        if (target_length) {
          const auto& o = c.target.offsets;
          r.frames = o[static_cast<size_t>(mine[k].row) + 1] - o[static_cast<size_t>(mine[k].row)];
        }
        requests.push_back(r);
      }
      auto edited = (*generator)->GenerateBatch(requests);
      if (!edited.ok()) return TaskReport::Error(edited.status().message());
      for (size_t k = at; k < end; ++k) {
        const TripletColumns& c = files[mine[k].file];
        Clip clip;
        clip.id = c.ids[static_cast<size_t>(mine[k].row)];
        clip.source = "edit:" + (*generator)->Name() + ":" + c.origin + "#" +
                      std::to_string(c.first_row + mine[k].row);
        clip.motion = std::move((*edited)[k - at]);
        clip.texts = {c.texts[static_cast<size_t>(mine[k].row)]};
        clips.push_back(std::move(clip));
      }
      if (ctx.on_metric) ctx.on_metric("edited", static_cast<double>(clips.size()));
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    if (!clips.empty()) {
      if (Status s = WriteClips(ctx.output_dir() + "/edited.npz", clips); !s.ok())
        return TaskReport::Error(s.message());
    }
    json summary = {
        {"model", (*generator)->Name()},
        {"checkpoint", checkpoint},
        {"split", split},
        {"edited", clips.size()},
        {"seconds", seconds},
        {"motions_per_second", static_cast<double>(clips.size()) / std::max(seconds, 1e-9)},
        {"sampler", p.value("sampler", std::string("ddpm"))},
        {"steps", p.value("steps", 0)}};
    const auto counts = (*generator)->Counts();
    for (const auto& [name, value] : counts) summary["counts"][name] = value;
    if (Status s = WriteFileAtomic(ctx.output_dir() + "/edits.json", summary.dump(1) + "\n");
        !s.ok())
      return TaskReport::Error(s.message());
    TaskReport out = TaskReport::Ok();
    out.metrics["edited"] = static_cast<double>(clips.size());
    out.metrics["motions_per_second"] = summary["motions_per_second"].get<double>();
    for (const auto& [name, value] : counts) out.metrics[name] = value;
    return out;
  }

 private:
  const PluginHost* plugins_;
};

}  // namespace

MP_STAGE_KIND("edit", EditStage);

}  // namespace motionpipe::stages
