// Built-in stage kinds: the diagnostic ones the engine's tests and benchmarks use, `corpus` and
// `filter`.
#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <thread>

#include "../executor.h"
#include "motionpipe/base/file.h"
#include "motionpipe/corpus/corpus.h"
#include "motionpipe/similarity/filter.h"

namespace motionpipe::worker {

namespace {

// The diagnostic kinds: `tasks` map tasks each (default: `shards:`).
class DiagnosticStage : public StageExecutor {
 public:
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = IntParam(plan.params, "tasks", plan.shards, 1, path, errors);
  }
};

// Does nothing: the dispatch benchmark's task.
class NoopStage : public DiagnosticStage {
 public:
  std::string Description() const override { return "does nothing (dispatch benchmarks)"; }
  TaskReport Run(TaskContext&) override { return TaskReport::Ok(); }
};

// Sleeps `ms` milliseconds, stopping early when cancelled.
class SleepStage : public DiagnosticStage {
 public:
  std::string Description() const override { return "sleeps params.ms milliseconds"; }
  TaskReport Run(TaskContext& ctx) override {
    const auto until =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(ctx.params.value("ms", 100));
    while (std::chrono::steady_clock::now() < until) {
      if (ctx.cancelled()) return TaskReport::Error("cancelled");
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return TaskReport::Ok();
  }
};

// Appends "stage index pid" to params.log (O_APPEND: lines from many processes never interleave).
void LogExecution(const TaskContext& ctx) {
  if (!ctx.params.contains("log")) return;
  const std::string line = ctx.spec.stage() + " " + std::to_string(ctx.spec.index()) + " " +
                           std::to_string(::getpid()) + "\n";
  const int fd = ::open(ctx.params["log"].get<std::string>().c_str(),
                        O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd >= 0) {
    (void)!::write(fd, line.data(), line.size());
    ::close(fd);
  }
}

// Writes out.txt whose content depends only on (seed, stage, index): the same bytes however often
// and wherever it runs, so chaos runs can be compared with an undisturbed one by checksum.
class WriteStage : public DiagnosticStage {
 public:
  std::string Description() const override {
    return "writes a deterministic file per task (tests)";
  }
  TaskReport Run(TaskContext& ctx) override {
    LogExecution(ctx);
    // `ms` delays every attempt, `first_attempt_ms` only the first (a slow worker whose lease
    // expires).
    int ms = ctx.params.value("ms", 0);
    if (ctx.spec.attempt() == 0) ms += ctx.params.value("first_attempt_ms", 0);
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    while (std::chrono::steady_clock::now() < until) {
      if (ctx.cancelled()) return TaskReport::Error("cancelled");
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    std::string content;
    const std::string seed = std::to_string(ctx.spec.seed()) + ":" + ctx.spec.stage() + ":" +
                             std::to_string(ctx.spec.index());
    const int blocks = std::max(1, ctx.params.value("bytes", 64) / 64);
    std::string digest = Sha256Hex(seed);
    for (int b = 0; b < blocks; ++b) {
      content += digest;
      digest = Sha256Hex(digest);
    }
    std::filesystem::create_directories(ctx.output_dir());
    // `sync: false` writes as the bulk outputs do (no fsync of its own; the worker syncs the task's
    // outputs before reporting them).
    if (const Status s =
            WriteFileAtomic(ctx.output_dir() + "/out.txt", content, ctx.params.value("sync", true));
        !s.ok()) {
      return TaskReport::Error(s.message());
    }
    return TaskReport::Ok();
  }
};

// Fails its first params.fail_times attempts (ERROR), or always with BAD_INPUT when
// params.bad_input.
class FailStage : public DiagnosticStage {
 public:
  std::string Description() const override { return "fails on purpose (tests)"; }
  TaskReport Run(TaskContext& ctx) override {
    LogExecution(ctx);
    if (ctx.params.value("bad_input", false))
      return TaskReport::BadInput("params.bad_input is set: this input can never work");
    const int fail_times = ctx.params.value("fail_times", 1 << 30);
    if (ctx.spec.attempt() < fail_times) {
      return TaskReport::Error("deliberate failure " + std::to_string(ctx.spec.attempt() + 1) +
                               " of " + std::to_string(fail_times));
    }
    return TaskReport::Ok();
  }
};

// Kills the whole worker process (SIGKILL on itself) when running task params.index (default: every
// task): a poison task.
class CrashStage : public DiagnosticStage {
 public:
  std::string Description() const override { return "kills its worker (poison tests)"; }
  TaskReport Run(TaskContext& ctx) override {
    LogExecution(ctx);
    const int index = ctx.params.value("index", -1);
    if (index < 0 || index == ctx.spec.index()) ::kill(::getpid(), SIGKILL);
    return TaskReport::Ok();
  }
};

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

// SimMotionEdit's dataset filter (similarity curves, MotionSNR, classes): shard tasks each filter
// their part of the triplet files; the reduce task writes the summary and its plot.
class FilterStage : public StageExecutor {
 public:
  // `shards` tasks (default 8) over the triplet files of the input stage or of params.triplets,
  // then a summary. The similarity constants are checked here, before anything runs.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    if (!plan.shards_set) plan.shards = 8;
    plan.reduce = true;
    const auto& p = plan.params;
    if (p.contains("triplets") && !p["triplets"].is_string() && !p["triplets"].is_array()) {
      errors->push_back(path + ".params.triplets: must be a path or a list of paths");
    }
    if (!p.contains("triplets") && plan.inputs.empty()) {
      errors->push_back(
          path +
          ": needs an input stage (inputs: [corpus]) or params.triplets (files or directories)");
    }
    if (p.contains("input") && (!p["input"].is_string() ||
                                std::find(plan.inputs.begin(), plan.inputs.end(),
                                          p["input"].get<std::string>()) == plan.inputs.end())) {
      errors->push_back(path + ".params.input: must name one of the stage's inputs");
    }
    auto options = similarity::OptionsFromJson(p, path + ".params", {"triplets", "input"});
    if (!options.ok()) errors->push_back(options.status().message());
  }
  std::string Description() const override {
    return "similarity curves, MotionSNR and classes of editing triplets";
  }
  TaskReport Run(TaskContext& ctx) override {
    const auto& p = ctx.params;
    auto options = similarity::OptionsFromJson(p, "params", {"triplets", "input"});
    if (!options.ok()) return TaskReport::BadInput(options.status().message());
    if (ctx.spec.reduce()) {
      const std::vector<std::string> shards(ctx.spec.shard_dirs().begin(),
                                            ctx.spec.shard_dirs().end());
      auto summary = similarity::SummarizeFilter(shards, ctx.output_dir());
      if (!summary.ok()) return TaskReport::FromStatus(summary.status());
      TaskReport report;
      report.metrics["triplets"] = (*summary)["triplets"].get<double>();
      report.metrics["kept"] = (*summary)["kept"].get<double>();
      report.message = similarity::FormatFilterSummary(*summary);
      return report;
    }
    std::vector<std::string> inputs;
    if (p.contains("triplets")) {
      if (p["triplets"].is_string())
        inputs.push_back(p["triplets"].get<std::string>());
      else
        for (const auto& v : p["triplets"]) inputs.push_back(v.get<std::string>());
    } else {
      const std::string stage =
          p.value("input", ctx.spec.inputs_size() > 0 ? ctx.spec.inputs(0).stage() : std::string());
      std::string dir = ctx.InputResult(stage);
      if (dir.empty()) {
        const auto dirs = ctx.InputDirs(stage);
        inputs.insert(inputs.end(), dirs.begin(), dirs.end());
      } else {
        inputs.push_back(dir);
      }
      if (inputs.empty()) return TaskReport::BadInput("input stage '" + stage + "' has no outputs");
    }
    auto files = similarity::ResolveTripletFiles(inputs);
    if (!files.ok()) return TaskReport::FromStatus(files.status());
    const auto slices = similarity::PlanShard(*files, ctx.spec.count(), ctx.spec.index());
    auto report = similarity::FilterShard(slices, *options, ctx.threads, ctx.output_dir());
    if (!report.ok()) return TaskReport::FromStatus(report.status());
    TaskReport out;
    out.metrics["triplets"] = static_cast<double>(report->triplets);
    out.metrics["kept"] = static_cast<double>(report->kept);
    out.metrics["triplets_per_second"] =
        static_cast<double>(report->triplets) / std::max(report->seconds, 1e-9);
    return out;
  }
};

}  // namespace

void RegisterBuiltinExecutors(ExecutorRegistry* registry, const PluginHost* plugins) {
  registry->Register("noop", std::make_unique<NoopStage>());
  registry->Register("sleep", std::make_unique<SleepStage>());
  registry->Register("test.write", std::make_unique<WriteStage>());
  registry->Register("test.fail", std::make_unique<FailStage>());
  registry->Register("test.crash", std::make_unique<CrashStage>());
  registry->Register("corpus", std::make_unique<CorpusStage>());
  registry->Register("filter", std::make_unique<FilterStage>());
  RegisterSincExecutors(registry, plugins);
  RegisterModelExecutors(registry, plugins);
}

}  // namespace motionpipe::worker
