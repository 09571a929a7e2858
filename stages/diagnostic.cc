// The diagnostic kinds the engine's tests and benchmarks use: noop, sleep, test.write, test.fail,
// test.crash.
#include <chrono>
#include <csignal>
#include <filesystem>
#include <thread>

#include "fcntl.h"
#include "motionpipe/base/file.h"
#include "stage.h"
#include "unistd.h"

namespace motionpipe::stages {

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

}  // namespace

MP_STAGE_KIND("noop", NoopStage);
MP_STAGE_KIND("sleep", SleepStage);
MP_STAGE_KIND("test.write", WriteStage);
MP_STAGE_KIND("test.fail", FailStage);
MP_STAGE_KIND("test.crash", CrashStage);

}  // namespace motionpipe::stages
