// Stages that run trained models through the torch-free generator interface (generators.h):
// `edit` edits the test split's triplets with an editing checkpoint (MDT, TMED, MDM, MDM-BP),
// sharded over workers, writing the edited motions as a clip file per task.
//
// params (edit): model (the input stage holding the checkpoint; default: the input that has one),
//   split (test), limit (0 = all), batch (8), sampler (ddpm | ddim), steps (DDIM steps), seed,
//   body_parts (MDM-BP), options (merged into the generator's configuration)
#include <algorithm>
#include <chrono>
#include <filesystem>

#include "../executor.h"
#include "../generators.h"
#include "motionpipe/base/file.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::worker {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Triplet files of the inputs: DIR/motionfix/triplets*.npz or DIR/triplets*.npz, sorted.
std::vector<std::string> TripletFiles(const TaskContext& ctx) {
  std::vector<std::string> files;
  for (const auto& input : ctx.spec.inputs()) {
    std::vector<std::string> dirs(input.dirs().begin(), input.dirs().end());
    if (!input.result_dir().empty()) dirs.push_back(input.result_dir());
    for (const auto& dir : dirs) {
      for (const std::string& folder : {dir, dir + "/motionfix"}) {
        if (!fs::is_directory(folder)) continue;
        for (const auto& entry : fs::directory_iterator(folder)) {
          const std::string name = entry.path().filename().string();
          if (name.rfind("triplets", 0) == 0 && entry.path().extension() == ".npz") files.push_back(entry.path().string());
        }
      }
    }
  }
  std::sort(files.begin(), files.end());
  files.erase(std::unique(files.begin(), files.end()), files.end());
  return files;
}

std::string FindCheckpoint(const TaskContext& ctx, const std::string& stage) {
  for (const auto& input : ctx.spec.inputs()) {
    if (!stage.empty() && input.stage() != stage) continue;
    for (const auto& dir : input.dirs()) {
      if (auto resolved = ResolveCheckpoint(dir); resolved.ok()) return *resolved;
    }
  }
  return "";
}

class EditStage : public StageExecutor {
 public:
  explicit EditStage(const PluginHost* plugins) : plugins_(plugins) {}
  std::string Description() const override { return "edits the test triplets with an editing checkpoint, sharded"; }

  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    if (!plugins_) return TaskReport::Error("edit: this worker has no plugin host");
    fs::create_directories(ctx.output_dir());
    const std::string checkpoint = FindCheckpoint(ctx, p.value("model", std::string()));
    if (checkpoint.empty()) return TaskReport::BadInput("edit: no input holds a checkpoint (a train stage's model/)");
    json options = p.value("options", json::object());
    if (p.value("body_parts", false)) options["body_parts"] = true;
    auto generator = LoadGenerator(*plugins_, checkpoint, options);
    if (!generator.ok()) return TaskReport::BadInput(generator.status().message());
    const std::string split = p.value("split", std::string("test"));
    const int64_t limit = p.value("limit", int64_t{0});
    const int batch_size = std::max(1, p.value("batch", 8));
    // Every triplet of the split, in file and row order; this task takes every count-th one.
    struct Item {
      size_t file;
      int64_t row;
    };
    std::vector<TripletColumns> files;
    std::vector<Item> items;
    for (const std::string& path : TripletFiles(ctx)) {
      auto columns = ReadTripletColumns(path, {0, -1, true, false});
      if (!columns.ok()) return TaskReport::BadInput(columns.status().message());
      for (int64_t r = 0; r < columns->rows; ++r) {
        if (columns->splits[static_cast<size_t>(r)] == split) items.push_back({files.size(), r});
      }
      files.push_back(std::move(*columns));
    }
    if (items.empty()) return TaskReport::BadInput("edit: no triplets of split '" + split + "' in the inputs");
    if (limit > 0 && static_cast<int64_t>(items.size()) > limit) items.resize(static_cast<size_t>(limit));
    std::vector<Item> mine;
    for (size_t k = static_cast<size_t>(ctx.spec.index()); k < items.size(); k += static_cast<size_t>(std::max(1, ctx.spec.count()))) {
      mine.push_back(items[k]);
    }
    const auto motion_of = [&](const Item& item, bool source) {
      const TripletColumns& c = files[item.file];
      const auto& side = source ? c.source : c.target;
      const int64_t begin = side.offsets[static_cast<size_t>(item.row)], end = side.offsets[static_cast<size_t>(item.row) + 1];
      Motion m;
      m.fps = c.fps[static_cast<size_t>(item.row)];
      m.poses.assign(side.poses + begin * side.joints * 3, side.poses + end * side.joints * 3);
      m.trans.assign(side.trans + begin * 3, side.trans + end * 3);
      return m;
    };
    std::vector<Clip> clips;
    const auto started = std::chrono::steady_clock::now();
    for (size_t at = 0; at < mine.size(); at += static_cast<size_t>(batch_size)) {
      if (ctx.cancelled()) return TaskReport::Error("cancelled");
      const size_t end = std::min(mine.size(), at + static_cast<size_t>(batch_size));
      std::vector<Motion> sources;
      for (size_t k = at; k < end; ++k) sources.push_back(motion_of(mine[k], true));
      std::vector<plugin::GenerateRequest> requests;
      for (size_t k = at; k < end; ++k) {
        const TripletColumns& c = files[mine[k].file];
        plugin::GenerateRequest r;
        r.texts = {c.texts[static_cast<size_t>(mine[k].row)]};
        r.source = &sources[k - at];
        r.seed = ctx.spec.seed() + static_cast<uint64_t>(at);
        r.sampler = p.value("sampler", std::string("ddpm"));
        r.steps = p.value("steps", 0);
        requests.push_back(r);
      }
      auto edited = (*generator)->GenerateBatch(requests);
      if (!edited.ok()) return TaskReport::Error(edited.status().message());
      for (size_t k = at; k < end; ++k) {
        const TripletColumns& c = files[mine[k].file];
        Clip clip;
        clip.id = c.ids[static_cast<size_t>(mine[k].row)];
        clip.source = "edit:" + (*generator)->Name() + ":" + c.origin + "#" + std::to_string(c.first_row + mine[k].row);
        clip.motion = std::move((*edited)[k - at]);
        clip.texts = {c.texts[static_cast<size_t>(mine[k].row)]};
        clips.push_back(std::move(clip));
      }
      if (ctx.on_metric) ctx.on_metric("edited", static_cast<double>(clips.size()));
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    if (!clips.empty()) {
      if (Status s = WriteClips(ctx.output_dir() + "/edited.npz", clips); !s.ok()) return TaskReport::Error(s.message());
    }
    const json summary = {{"model", (*generator)->Name()}, {"checkpoint", checkpoint}, {"split", split}, {"edited", clips.size()},
                          {"seconds", seconds}, {"motions_per_second", static_cast<double>(clips.size()) / std::max(seconds, 1e-9)},
                          {"sampler", p.value("sampler", std::string("ddpm"))}, {"steps", p.value("steps", 0)}};
    if (Status s = WriteFileAtomic(ctx.output_dir() + "/edits.json", summary.dump(1) + "\n"); !s.ok()) return TaskReport::Error(s.message());
    TaskReport out = TaskReport::Ok();
    out.metrics["edited"] = static_cast<double>(clips.size());
    out.metrics["motions_per_second"] = summary["motions_per_second"].get<double>();
    return out;
  }

 private:
  const PluginHost* plugins_;
};

}  // namespace

void RegisterModelExecutors(ExecutorRegistry* registry, const PluginHost* plugins) {
  registry->Register("edit", std::make_unique<EditStage>(plugins));
}

}  // namespace motionpipe::worker
