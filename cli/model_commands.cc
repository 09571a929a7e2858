// `motionpipe generate`: run a trained text-to-motion checkpoint (TEMOS/SINC and its baselines) and
// write the motion as a clip file or a BVH. `motionpipe edit`: edit a user's motion (clip file,
// AMASS npz or BVH) with a trained editor (MDT, TMED, MDM, MDM-BP). Torch stays in the plugins: the
// checkpoint's model.json names the plugin that loads it.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>

#include "commands.h"
#include "generators.h"
#include "motionpipe/base/file.h"
#include "motionpipe/formats/bvh.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/render/motion_render.h"
#include "motionpipe/sinc/texts.h"
#include "report.h"

namespace motionpipe::cli {

namespace {

int Fail(const Status& status) {
  std::cerr << "error: " << status.message() << "\n";
  return kExitFailure;
}

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

worker::PluginHost LoadPlugins(const std::vector<std::string>& extra) {
  worker::PluginHost host;
  for (const std::string& d : extra) host.LoadDirectory(d);
  for (const std::string& d : worker::DefaultPluginDirs()) host.LoadDirectory(d);
  return host;
}

// A generated motion as a clip: its text(s), one segment per action over the whole clip.
Status WriteMotion(const std::string& out, const Motion& motion,
                   const std::vector<std::string>& texts, const std::string& source) {
  if (EndsWith(out, ".bvh")) return ExportBvhFile(out, motion, {});
  if (!EndsWith(out, ".npz"))
    return InvalidArgument(out + ": the output must end in .npz (clip file) or .bvh");
  Clip clip;
  clip.id = "generated";
  clip.source = source;
  clip.motion = motion;
  clip.joints = ComputeJoints(Skeleton::Smpl22(), motion);
  clip.texts = {texts.size() == 1 ? texts[0] : sinc::EvalPairText(texts[0], texts[1])};
  for (const std::string& t : texts)
    clip.segments.push_back({0, static_cast<int32_t>(motion.num_frames()), t, 0, ""});
  return WriteClips(out, {clip});
}

}  // namespace

void AddModelCommands(CLI::App& app, int* exit_code) {
  {  // render
    auto* cmd = app.add_subcommand(
        "render", "Render motions as a skeleton animation (GIF) or film strip (PNG), side by side");
    static std::vector<std::string> inputs, titles;
    static std::string out, clip_id;
    static render::RenderOptions options;
    static double source_fps = 30;
    cmd->add_option("motions", inputs,
                    "Motion files (clip .npz, AMASS npz, BVH): one panel each, side by side")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--out", out, "Output: .gif (animation) or .png (film strip)")->required();
    cmd->add_option("--title", titles, "Panel titles, in order (default: the clip id)");
    cmd->add_option("--clip", clip_id,
                    "Clip id to take from files holding several (default: the first)");
    cmd->add_option("--fps", options.fps, "GIF frame rate")
        ->capture_default_str()
        ->check(CLI::Range(1.0, 60.0));
    cmd->add_option("--size", options.panel_width, "Panel width and height in pixels")
        ->capture_default_str()
        ->check(CLI::Range(64, 2048));
    cmd->add_option("--frames", options.strip_frames, "PNG film strip: frames per panel")
        ->capture_default_str()
        ->check(CLI::Range(1, 64));
    cmd->add_option("--source-fps", source_fps, "Frame rate to resample BVH/AMASS inputs to")
        ->capture_default_str();
    cmd->callback([exit_code] {
      options.panel_height = options.panel_width;
      std::vector<render::MotionPanel> panels;
      for (size_t k = 0; k < inputs.size(); ++k) {
        auto clips = LoadMotionFile(inputs[k], source_fps);
        if (!clips.ok()) return void(*exit_code = Fail(clips.status()));
        const auto it = clip_id.empty()
                            ? clips->begin()
                            : std::find_if(clips->begin(), clips->end(),
                                           [](const Clip& c) { return c.id == clip_id; });
        if (it == clips->end())
          return void(*exit_code = Fail(NotFound(inputs[k] + ": no clip '" + clip_id + "'")));
        render::MotionPanel panel;
        panel.motion = it->motion;
        panel.title = k < titles.size() ? titles[k] : it->id;
        if (!it->texts.empty()) panel.caption = it->texts.front();
        panels.push_back(std::move(panel));
      }
      const auto started = std::chrono::steady_clock::now();
      if (Status s = render::RenderMotionFile(out, panels, options); !s.ok())
        return void(*exit_code = Fail(s));
      std::printf(
          "rendered %zu motion(s) -> %s in %.1f s\n", panels.size(), out.c_str(),
          std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
    });
  }
  {  // report
    auto* cmd = app.add_subcommand(
        "report",
        "Write a job's self-contained HTML report: the papers' tables, claims, curves, previews");
    static worker::ReportOptions options;
    static bool no_previews = false;
    cmd->add_option("job", options.job_dir, "The job's output directory, e.g. out/demo-1")
        ->required()
        ->check(CLI::ExistingDirectory);
    cmd->add_option("--out", options.out_path, "Output HTML (default: JOB/report.html)");
    cmd->add_option("--history", options.history, "An evaluation history (SQLite) to plot")
        ->check(CLI::ExistingFile);
    cmd->add_option("--title", options.title, "Report title (default: the job directory's name)");
    cmd->add_option("--size", options.panel_size, "Preview panel size in pixels")
        ->capture_default_str()
        ->check(CLI::Range(64, 1024));
    cmd->add_flag("--no-previews", no_previews, "Skip the rendered previews");
    cmd->add_option("--papers", options.papers,
                    "Paper files (the format of configs/papers/*.yaml) beside the built-in ones; "
                    "one of a built-in paper's name replaces it")
        ->check(CLI::ExistingFile);
    cmd->callback([exit_code] {
      options.previews = !no_previews;
      const auto started = std::chrono::steady_clock::now();
      auto summary = worker::WriteReport(options);
      if (!summary.ok()) return void(*exit_code = Fail(summary.status()));
      std::printf(
          "report: %d editing and %d composition methods, %d train stages, %d tables, %d images -> "
          "%s in %.1f s\n",
          summary->edit_methods, summary->generation_methods, summary->train_stages,
          summary->tables, summary->images, summary->path.c_str(),
          std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
      for (const worker::ClaimCheck& c : summary->claims) {
        std::printf("  %-13s %-50s %-40s %s\n", c.paper.c_str(), c.claim.c_str(), c.verdict.c_str(),
                    c.detail.c_str());
      }
    });
  }
  {  // edit
    auto* cmd = app.add_subcommand(
        "edit",
        "Edit a motion from a text instruction with a trained editor (MDT, TMED, MDM, MDM-BP)");
    static std::string model, source_path, clip_id, text, out, sampler = "ddpm";
    static std::vector<std::string> plugin_dirs;
    static int steps = 0;
    static uint64_t seed = 1;
    static double fps = 30;
    static bool body_parts = false;
    cmd->add_option(
           "--model", model,
           "Checkpoint: a model/ directory, a train task's output or a train stage's output")
        ->required();
    cmd->add_option("--source", source_path,
                    "The motion to edit: clip file (.npz), AMASS npz or BVH")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--clip", clip_id,
                    "Clip id when the source file holds several (default: the first)");
    cmd->add_option("--text", text, "The edit instruction, e.g. \"raise the right arm higher\"")
        ->required();
    cmd->add_option("--out", out, "Output: .npz (clip file) or .bvh (SMPL-22 BVH)")->required();
    cmd->add_option("--sampler", sampler, "ddpm (every step) or ddim")
        ->capture_default_str()
        ->check(CLI::IsMember({"ddpm", "ddim"}));
    cmd->add_option("--steps", steps, "DDIM steps (default 50)")->check(CLI::Range(1, 100000));
    cmd->add_option("--seed", seed, "Sampling seed")->capture_default_str();
    cmd->add_option("--fps", fps, "Frame rate to resample BVH/AMASS sources to")
        ->capture_default_str()
        ->check(CLI::Range(1.0, 240.0));
    cmd->add_flag(
        "--body-parts", body_parts,
        "MDM checkpoints: keep the body parts the text does not involve from the source (MDM-BP)");
    cmd->add_option("--plugins", plugin_dirs, "Extra plugin directories");
    cmd->callback([exit_code] {
      if (!EndsWith(out, ".npz") && !EndsWith(out, ".bvh")) {
        return void(*exit_code = Fail(InvalidArgument(
                        out + ": the output must end in .npz (clip file) or .bvh")));
      }
      auto clips = LoadMotionFile(source_path, fps);
      if (!clips.ok()) return void(*exit_code = Fail(clips.status()));
      const auto it = clip_id.empty() ? clips->begin()
                                      : std::find_if(clips->begin(), clips->end(),
                                                     [](const Clip& c) { return c.id == clip_id; });
      if (it == clips->end())
        return void(*exit_code = Fail(NotFound(source_path + ": no clip '" + clip_id + "'")));
      const worker::PluginHost host = LoadPlugins(plugin_dirs);
      nlohmann::json options = nlohmann::json::object();
      if (body_parts) options["body_parts"] = true;
      auto generator = worker::LoadGenerator(host, model, options);
      if (!generator.ok()) return void(*exit_code = Fail(generator.status()));
      plugin::GenerateRequest request;
      request.texts = {text};
      request.source = &it->motion;
      request.seed = seed;
      request.sampler = sampler;
      request.steps = steps;
      const auto started = std::chrono::steady_clock::now();
      auto edited = (*generator)->Generate(request);
      if (!edited.ok()) return void(*exit_code = Fail(edited.status()));
      const double seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
      if (Status s = WriteMotion(out, *edited, {text},
                                 "motionpipe:edit:" + (*generator)->Name() + ":" + it->source);
          !s.ok()) {
        return void(*exit_code = Fail(s));
      }
      std::printf("%s: edited %s (%lld frames) with \"%s\" in %.1f s (%s) -> %s\n",
                  (*generator)->Name().c_str(), it->id.c_str(),
                  static_cast<long long>(edited->num_frames()), text.c_str(), seconds,
                  sampler == "ddim"
                      ? ("DDIM " + std::to_string(steps > 0 ? steps : 50) + " steps").c_str()
                      : "DDPM",
                  out.c_str());
    });
  }
  auto* cmd = app.add_subcommand(
      "generate",
      "Generate a motion from text with a trained checkpoint (TEMOS/SINC and baselines)");
  static std::string model, out;
  static std::vector<std::string> texts, plugin_dirs;
  static double seconds = 4, fps = 30;
  static uint64_t seed = 1;
  static bool compositing = false;
  cmd->add_option("--model", model,
                  "Checkpoint: a model/ directory, a train task's output or a train stage's output")
      ->required();
  cmd->add_option("--text", texts, "Action text; give it twice for two simultaneous actions")
      ->required();
  cmd->add_option("--seconds", seconds, "Duration")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 300.0));
  cmd->add_option("--fps", fps, "Frame rate")->capture_default_str()->check(CLI::Range(1.0, 240.0));
  cmd->add_option("--seed", seed, "Sampling seed")->capture_default_str();
  cmd->add_option("--out", out, "Output: .npz (clip file) or .bvh (SMPL-22 BVH)")->required();
  cmd->add_flag("--compositing", compositing,
                "Single-action checkpoints: generate each action alone and compose them by the "
                "labeler's body parts");
  cmd->add_option("--plugins", plugin_dirs, "Extra plugin directories");
  cmd->callback([exit_code] {
    if (texts.size() > 2)
      return void(*exit_code = Fail(
                      InvalidArgument("generate: at most two --text (two simultaneous actions)")));
    if (!EndsWith(out, ".npz") && !EndsWith(out, ".bvh")) {
      return void(*exit_code = Fail(
                      InvalidArgument(out + ": the output must end in .npz (clip file) or .bvh")));
    }
    const worker::PluginHost host = LoadPlugins(plugin_dirs);
    nlohmann::json options = nlohmann::json::object();
    if (compositing) options["compositing"] = true;
    auto generator = worker::LoadGenerator(host, model, options);
    if (!generator.ok()) return void(*exit_code = Fail(generator.status()));
    plugin::GenerateRequest request;
    request.texts = texts;
    request.seconds = seconds;
    request.fps = fps;
    request.seed = seed;
    auto motion = (*generator)->Generate(request);
    if (!motion.ok()) return void(*exit_code = Fail(motion.status()));
    if (Status s = WriteMotion(out, *motion, texts, "motionpipe:generate:" + (*generator)->Name());
        !s.ok()) {
      return void(*exit_code = Fail(s));
    }
    std::printf("%s: %lld frames at %.0f fps (%.2f s) from %s -> %s\n",
                (*generator)->Name().c_str(), static_cast<long long>(motion->num_frames()),
                motion->fps, static_cast<double>(motion->num_frames()) / motion->fps, model.c_str(),
                out.c_str());
  });
}

}  // namespace motionpipe::cli
