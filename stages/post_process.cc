#include "post_process.h"

#include <filesystem>

#include "inputs.h"
#include "motionpipe/base/file.h"
#include "motionpipe/formats/clip.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

// The clip files a post-process reads and writes, each with its stage's summary.
struct Layout {
  const char* clips;
  const char* summary;
};
constexpr Layout kLayouts[] = {{"edited.npz", "edits.json"}, {"generated.npz", "generate.json"}};

}  // namespace

TaskReport PostProcessMotions(TaskContext& ctx, const PostProcess& post) {
  fs::create_directories(ctx.output_dir());
  int64_t motions = 0;
  for (const Layout& layout : kLayouts) {
    std::vector<Clip> clips;
    json summary;
    for (const std::string& dir : StageDirs(ctx, post.motions)) {
      if (!fs::exists(dir + "/" + layout.clips)) continue;
      auto read = ReadClips(dir + "/" + layout.clips);
      if (!read.ok()) return TaskReport::BadInput(post.kind + ": " + read.status().message());
      for (Clip& clip : *read) {
        if (ctx.cancelled()) return TaskReport::Error("cancelled");
        auto changed = post.change(clip.motion);
        if (!changed.ok())
          return TaskReport::BadInput(post.kind + ": " + dir + "/" + layout.clips + ", " + clip.id +
                                      ": " + changed.status().message());
        clip.motion = std::move(*changed);
        clips.push_back(std::move(clip));
      }
      if (summary.is_null()) {
        auto text = ReadFile(dir + "/" + layout.summary);
        if (text.ok()) summary = json::parse(*text, nullptr, false);
      }
    }
    if (clips.empty()) continue;
    motions += static_cast<int64_t>(clips.size());
    if (Status s = WriteClips(ctx.output_dir() + "/" + layout.clips, clips); !s.ok())
      return TaskReport::Error(s.message());
    // The input's model and checkpoint (what eval_edit/eval_generate name the row by), marked.
    const json input = summary.is_object() ? summary : json::object();
    summary = {{"model", input.value("model", std::string("motions")) + " + " + post.label},
               {"checkpoint", input.value("checkpoint", std::string())},
               {"input", input}};
    summary[post.key] = post.summarise(static_cast<int64_t>(clips.size()));
    if (Status s = WriteFileAtomic(ctx.output_dir() + "/" + layout.summary, summary.dump(1) + "\n");
        !s.ok())
      return TaskReport::Error(s.message());
  }
  if (motions == 0)
    return TaskReport::BadInput(post.kind +
                                ": no edited.npz or generated.npz in the inputs (an edit or "
                                "generate stage)");
  TaskReport out = TaskReport::Ok();
  out.metrics["motions"] = static_cast<double>(motions);
  return out;
}

}  // namespace motionpipe::stages
