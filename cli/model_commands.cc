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
#include "post_process.h"
#include "report.h"

namespace motionpipe::cli {

namespace {

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

// ---- render ------------------------------------------------------------------------------------
struct RenderArgs {
  std::vector<std::string> inputs, titles;
  std::string out, clip_id;
  render::RenderOptions options;
  double fps = 30;  // the inputs are resampled to this rate; options.fps is the GIF's
};

int RunRender(const RenderArgs& a) {
  render::RenderOptions options = a.options;
  options.panel_height = options.panel_width;
  std::vector<render::MotionPanel> panels;
  for (size_t k = 0; k < a.inputs.size(); ++k) {
    auto clips = LoadMotionFile(a.inputs[k], a.fps);
    if (!clips.ok()) return Fail(clips.status());
    auto clip = FindClip(*clips, a.clip_id, a.inputs[k]);
    if (!clip.ok()) return Fail(clip.status());
    render::MotionPanel panel;
    panel.motion = (*clip)->motion;
    panel.title = k < a.titles.size() ? a.titles[k] : (*clip)->id;
    if (!(*clip)->texts.empty()) panel.caption = (*clip)->texts.front();
    panels.push_back(std::move(panel));
  }
  const auto started = std::chrono::steady_clock::now();
  if (Status s = render::RenderMotionFile(a.out, panels, options); !s.ok()) return Fail(s);
  std::printf("rendered %zu motion(s) -> %s in %.1f s\n", panels.size(), a.out.c_str(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
  return kExitOk;
}

void AddRender(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "render", "Render motions as a skeleton animation (GIF) or film strip (PNG), side by side");
  static RenderArgs a;
  cmd->add_option("motions", a.inputs,
                  "Motion files (clip .npz, AMASS npz, BVH): one panel each, side by side")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", a.out, "Output: .gif (animation) or .png (film strip)")->required();
  cmd->add_option("--title", a.titles, "Panel titles, in order (default: the clip id)");
  cmd->add_option("--clip", a.clip_id,
                  "Clip id to take from files holding several (default: the first)");
  cmd->add_option("--gif-fps", a.options.fps, "GIF frame rate (frames shown per second)")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 60.0));
  // --fps resamples the inputs, as in `edit`, `data import-bvh` and `data roundtrip`.
  cmd->add_option("--fps,--source-fps", a.fps, "Frame rate to resample BVH/AMASS inputs to")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 240.0));
  cmd->add_option("--size", a.options.panel_width, "Panel width and height in pixels")
      ->capture_default_str()
      ->check(CLI::Range(64, 2048));
  cmd->add_option("--frames", a.options.strip_frames, "PNG film strip: frames per panel")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  cmd->callback([exit_code] { *exit_code = RunRender(a); });
}

// ---- report ------------------------------------------------------------------------------------
struct ReportArgs {
  report::ReportOptions options;
  bool no_previews = false;
};

int RunReport(const ReportArgs& a) {
  report::ReportOptions options = a.options;
  options.previews = !a.no_previews;
  const auto started = std::chrono::steady_clock::now();
  auto summary = report::WriteReport(options);
  if (!summary.ok()) return Fail(summary.status());
  std::string methods;  // "1 edit and 0 generate methods"
  for (const auto& [evaluation, count] : summary->methods)
    methods += (methods.empty() ? "" : " and ") + std::to_string(count) + " " + evaluation;
  std::printf("report: %s methods, %d train stages, %d tables, %d images -> %s in %.1f s\n",
              methods.empty() ? "no" : methods.c_str(), summary->train_stages, summary->tables,
              summary->images, summary->path.c_str(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
  for (const report::ClaimCheck& c : summary->claims) {
    std::printf("  %-13s %-50s %-40s %s\n", c.paper.c_str(), c.claim.c_str(), c.verdict.c_str(),
                c.detail.c_str());
  }
  return kExitOk;
}

void AddReport(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "report",
      "Write a job's self-contained HTML report: the papers' tables, claims, curves, previews");
  static ReportArgs a;
  report::ReportOptions& options = a.options;
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
  cmd->add_flag("--no-previews", a.no_previews, "Skip the rendered previews");
  cmd->add_option("--papers", options.papers,
                  "Paper files (the format of configs/papers/*.yaml) beside the built-in ones; "
                  "one of a built-in paper's name replaces it")
      ->check(CLI::ExistingFile);
  cmd->callback([exit_code] { *exit_code = RunReport(a); });
}

// ---- edit --------------------------------------------------------------------------------------
struct EditArgs {
  std::string model, source_path, clip_id, text, out, sampler = "ddpm";
  std::vector<std::string> plugin_dirs;
  int steps = 0;
  uint64_t seed = 1;
  double fps = 30;
  bool body_parts = false;
  PostProcessArgs post;
};

int RunEdit(const EditArgs& a) {
  if (!EndsWith(a.out, ".npz") && !EndsWith(a.out, ".bvh"))
    return Usage(a.out + ": the output must end in .npz (clip file) or .bvh");
  auto clips = LoadMotionFile(a.source_path, a.fps);
  if (!clips.ok()) return Fail(clips.status());
  auto found = FindClip(*clips, a.clip_id, a.source_path);
  if (!found.ok()) return Fail(found.status());
  const Clip& source = **found;
  if (Status s = CheckPostProcesses(a.post); !s.ok()) return Fail(s);
  const worker::PluginHost host = LoadPlugins(a.plugin_dirs);
  nlohmann::json options = nlohmann::json::object();
  if (a.body_parts) options["body_parts"] = true;
  auto generator = worker::LoadGenerator(host, a.model, options);
  if (!generator.ok()) return Fail(generator.status());
  plugin::GenerateRequest request;
  request.texts = {a.text};
  request.source = &source.motion;
  request.seed = a.seed;
  request.sampler = a.sampler;
  request.steps = a.steps;
  const auto started = std::chrono::steady_clock::now();
  auto edited = (*generator)->Generate(request);
  if (!edited.ok()) return Fail(edited.status());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  auto final_motion = ApplyPostProcesses(a.post, host, *edited);
  if (!final_motion.ok()) return Fail(final_motion.status());
  if (Status s = WriteMotion(
          a.out, *final_motion, {a.text},
          "motionpipe:edit:" + (*generator)->Name() + a.post.Suffix() + ":" + source.source);
      !s.ok()) {
    return Fail(s);
  }
  const std::string how = a.sampler == "ddim"
                              ? "DDIM " + std::to_string(a.steps > 0 ? a.steps : 50) + " steps"
                              : "DDPM";
  std::printf("%s: edited %s (%lld frames) with \"%s\" in %.1f s (%s) -> %s\n",
              (*generator)->Name().c_str(), source.id.c_str(),
              static_cast<long long>(edited->num_frames()), a.text.c_str(), seconds, how.c_str(),
              a.out.c_str());
  return kExitOk;
}

void AddEdit(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "edit",
      "Edit a motion from a text instruction with a trained editor (MDT, TMED, MDM, MDM-BP)");
  static EditArgs a;
  cmd->add_option("--model", a.model,
                  "Checkpoint: a model/ directory, a train task's output or a train stage's output")
      ->required();
  cmd->add_option("--source", a.source_path,
                  "The motion to edit: clip file (.npz), AMASS npz or BVH")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--clip", a.clip_id,
                  "Clip id when the source file holds several (default: the first)");
  cmd->add_option("--text", a.text, "The edit instruction, e.g. \"raise the right arm higher\"")
      ->required();
  cmd->add_option("--out", a.out, "Output: .npz (clip file) or .bvh (SMPL-22 BVH)")->required();
  cmd->add_option("--sampler", a.sampler, "ddpm (every step) or ddim")
      ->capture_default_str()
      ->check(CLI::IsMember({"ddpm", "ddim"}));
  cmd->add_option("--steps", a.steps, "DDIM steps (default 50)")->check(CLI::Range(1, 100000));
  cmd->add_option("--seed", a.seed, "Sampling seed")->capture_default_str();
  cmd->add_option("--fps", a.fps, "Frame rate to resample BVH/AMASS sources to")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 240.0));
  cmd->add_flag(
      "--body-parts", a.body_parts,
      "MDM checkpoints: keep the body parts the text does not involve from the source (MDM-BP)");
  AddPostProcessOptions(cmd, &a.post);
  cmd->add_option("--plugins", a.plugin_dirs, "Extra plugin directories");
  cmd->callback([exit_code] { *exit_code = RunEdit(a); });
}

// ---- generate ----------------------------------------------------------------------------------
struct GenerateArgs {
  std::string model, out;
  std::vector<std::string> texts, plugin_dirs;
  double seconds = 4, fps = 30;
  uint64_t seed = 1;
  bool compositing = false;
  PostProcessArgs post;
};

int RunGenerate(const GenerateArgs& a) {
  if (a.texts.size() > 2) return Usage("generate: at most two --text (two simultaneous actions)");
  if (!EndsWith(a.out, ".npz") && !EndsWith(a.out, ".bvh"))
    return Usage(a.out + ": the output must end in .npz (clip file) or .bvh");
  if (Status s = CheckPostProcesses(a.post); !s.ok()) return Fail(s);
  const worker::PluginHost host = LoadPlugins(a.plugin_dirs);
  nlohmann::json options = nlohmann::json::object();
  if (a.compositing) options["compositing"] = true;
  auto generator = worker::LoadGenerator(host, a.model, options);
  if (!generator.ok()) return Fail(generator.status());
  plugin::GenerateRequest request;
  request.texts = a.texts;
  request.seconds = a.seconds;
  request.fps = a.fps;
  request.seed = a.seed;
  auto generated = (*generator)->Generate(request);
  if (!generated.ok()) return Fail(generated.status());
  auto motion = ApplyPostProcesses(a.post, host, *generated);
  if (!motion.ok()) return Fail(motion.status());
  if (Status s = WriteMotion(a.out, *motion, a.texts,
                             "motionpipe:generate:" + (*generator)->Name() + a.post.Suffix());
      !s.ok()) {
    return Fail(s);
  }
  std::printf("%s: %lld frames at %.0f fps (%.2f s) from %s -> %s\n", (*generator)->Name().c_str(),
              static_cast<long long>(motion->num_frames()), motion->fps,
              static_cast<double>(motion->num_frames()) / motion->fps, a.model.c_str(),
              a.out.c_str());
  return kExitOk;
}

void AddGenerate(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "generate",
      "Generate a motion from text with a trained checkpoint (TEMOS/SINC and baselines)");
  static GenerateArgs a;
  cmd->add_option("--model", a.model,
                  "Checkpoint: a model/ directory, a train task's output or a train stage's output")
      ->required();
  cmd->add_option("--text", a.texts, "Action text; give it twice for two simultaneous actions")
      ->required();
  cmd->add_option("--seconds", a.seconds, "Duration")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 300.0));
  cmd->add_option("--fps", a.fps, "Frame rate of the generated motion")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 240.0));
  cmd->add_option("--seed", a.seed, "Sampling seed")->capture_default_str();
  cmd->add_option("--out", a.out, "Output: .npz (clip file) or .bvh (SMPL-22 BVH)")->required();
  cmd->add_flag("--compositing", a.compositing,
                "Single-action checkpoints: generate each action alone and compose them by the "
                "labeler's body parts");
  AddPostProcessOptions(cmd, &a.post);
  cmd->add_option("--plugins", a.plugin_dirs, "Extra plugin directories");
  cmd->callback([exit_code] { *exit_code = RunGenerate(a); });
}

}  // namespace

void AddModelCommands(CLI::App& app, int* exit_code) {
  AddRender(app, exit_code);
  AddReport(app, exit_code);
  AddEdit(app, exit_code);
  AddGenerate(app, exit_code);
}

}  // namespace motionpipe::cli
