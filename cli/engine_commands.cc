// `motionpipe run | coordinator | worker | submit | status | wait | cancel | plugins | keys`.
#include <google/protobuf/util/json_util.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <thread>

#include "commands.h"
#include "control_client.h"
#include "journal.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/log.h"
#include "motionpipe/net/security.h"
#include "pipeline.h"
#include "plugin_host.h"
#include "server.h"
#include "worker.h"

namespace motionpipe::cli {

namespace {

std::atomic<int> g_run_signal{0};
extern "C" void OnRunSignal(int signal) { g_run_signal = signal; }

void AddDurationOption(CLI::App* cmd, const std::string& name, double* seconds,
                       const std::string& help) {
  cmd->add_option_function<std::string>(
         name,
         [seconds, name](const std::string& text) {
           if (!coordinator::ParseDuration(text, seconds))
             throw CLI::ValidationError(name, "expected a duration like 1s, 500ms, 2m");
         },
         help)
      ->type_name("DURATION");
}

std::string JsonOf(const google::protobuf::Message& message) {
  std::string json;
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = true;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields =
      true;  // a stable schema: `"jobs": []` when there are none
  (void)google::protobuf::util::MessageToJsonString(message, &json, options);
  return json;
}

Result<wire::ControlReply> StatusOf(const std::string& endpoint, int64_t job) {
  wire::ControlRequest request;
  request.mutable_status()->set_job_id(job);
  return Control(endpoint, request);
}

// Spawns `motionpipe worker ...` with this same binary. The worker dies with `run` (which holds the
// coordinator): a SIGKILLed `run` left its workers reconnecting for ever (issue 17). Called from
// the main thread, whose exit is the process's (PR_SET_PDEATHSIG fires when the forking thread
// ends).
pid_t SpawnWorker(const std::vector<std::string>& args) {
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid != 0) return pid;
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (::getppid() != parent) std::_Exit(1);  // `run` died before prctl took effect
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  ::execv("/proc/self/exe", argv.data());
  std::perror("exec motionpipe worker");
  std::_Exit(127);
}

// ---- run ---------------------------------------------------------------------------------------
struct RunArgs {
  std::string pipeline;
  std::vector<std::string> overrides;
  int workers = 2;
  int threads = 0;
  int credit = 0;
  std::string journal;
  std::string metrics;
  std::vector<std::string> plugin_dirs;
  double heartbeat = 1.0;
  bool quiet = false;
  bool dry_run = false;
  bool print_resolved = false;
};

// `run --dry-run`: the pipeline as planned (after overrides and validation), one line per stage
// with its task count; nothing is started or written.
int DryRun(const coordinator::PipelineSpec& spec) {
  std::printf("pipeline '%s': %zu stage(s); outputs in %s/%s-<job id>; fingerprint %s\n",
              spec.name.c_str(), spec.stages.size(), spec.output_root.c_str(), spec.name.c_str(),
              spec.fingerprint.substr(0, 12).c_str());
  std::printf("  %-28s %-16s %6s  %s\n", "stage", "kind", "tasks", "inputs");
  int64_t total = 0;
  for (const coordinator::StageSpec& stage : spec.stages) {
    const int tasks = stage.shards + (stage.reduce ? 1 : 0);
    total += tasks;
    std::string inputs;
    for (const std::string& input : stage.inputs) inputs += (inputs.empty() ? "" : ", ") + input;
    if (stage.world_size > 1) inputs += " (a gang of " + std::to_string(stage.world_size) + ")";
    std::printf("  %-28s %-16s %6d  %s\n", stage.name.c_str(), stage.kind.c_str(), tasks,
                inputs.c_str());
  }
  std::printf("%lld task(s) in all\n", static_cast<long long>(total));
  return 0;
}

// The id of an unfinished job of this very pipeline (same fingerprint) in the journal, or 0: `run`
// resumes it instead of starting the pipeline again.
Result<int64_t> UnfinishedJobOf(const std::string& journal, const std::string& fingerprint) {
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(journal).parent_path(), ec);
  MP_ASSIGN_OR_RETURN(auto j, coordinator::Journal::Open(journal));
  MP_ASSIGN_OR_RETURN(const auto unfinished, j->LoadUnfinished());
  int64_t job_id = 0;
  for (const auto& job : unfinished) {
    if (job.fingerprint == fingerprint) job_id = job.id;
  }
  return job_id;
}

// `run`'s coordinator: a thread of this process on ephemeral loopback ports.
class LocalCoordinator {
 public:
  ~LocalCoordinator() { Stop(); }

  // Returns once the coordinator listens (or failed to start).
  Status Start(const RunArgs& a, const std::string& journal) {
    coordinator::CoordinatorOptions options;
    options.bind = "tcp://127.0.0.1:*";
    options.control = "tcp://127.0.0.1:*";
    options.journal = journal;
    options.metrics_bind = a.metrics;
    options.plugin_dirs = a.plugin_dirs;
    options.heartbeat_seconds = a.heartbeat;
    thread_ = std::thread([this, options] {
      status_ = coordinator::RunCoordinator(options, &stop_, false,
                                            [this](const std::string& w, const std::string& c) {
                                              worker_endpoint_ = w;
                                              control_endpoint_ = c;
                                              ready_ = true;
                                            });
      ready_ = true;
    });
    while (!ready_) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (status_.ok() && !worker_endpoint_.empty()) return Status::Ok();
    Stop();
    return status_.ok() ? Internal("coordinator failed to start") : status_;
  }

  void Stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }

  const std::string& worker_endpoint() const { return worker_endpoint_; }
  const std::string& control_endpoint() const { return control_endpoint_; }

 private:
  std::atomic<bool> stop_{false}, ready_{false};
  std::thread thread_;
  Status status_;
  std::string worker_endpoint_, control_endpoint_;
};

// `run`'s workers: child processes of this binary, started again when one dies (a crashing task,
// OOM...), at most 100 times in all.
class LocalWorkers {
 public:
  LocalWorkers(const RunArgs& a, std::string coordinator, int threads)
      : args_(a), coordinator_(std::move(coordinator)), threads_(threads) {}
  ~LocalWorkers() { Stop(); }

  void Start() {
    pids_.resize(static_cast<size_t>(args_.workers));
    for (int k = 0; k < args_.workers; ++k) pids_[static_cast<size_t>(k)] = SpawnWorker(Argv(k));
  }

  void RestartTheDead() {
    for (size_t k = 0; k < pids_.size(); ++k) {
      int status = 0;
      if (pids_[k] <= 0 || ::waitpid(pids_[k], &status, WNOHANG) != pids_[k]) continue;
      if (restarts_++ >= 100) {
        pids_[k] = -1;
        continue;
      }
      MP_LOG(kWarn, "run") << "worker local-" << k << " exited ("
                           << (WIFSIGNALED(status) ? "signal " + std::to_string(WTERMSIG(status))
                                                   : "code " + std::to_string(WEXITSTATUS(status)))
                           << "); restarting it";
      pids_[k] = SpawnWorker(Argv(static_cast<int>(k)));
    }
  }

  // SIGTERM, then SIGKILL for a worker still alive 5 s later.
  void Stop() {
    for (pid_t pid : pids_) {
      if (pid > 0) ::kill(pid, SIGTERM);
    }
    for (pid_t pid : pids_) {
      if (pid <= 0) continue;
      for (int k = 0; k < 100 && ::waitpid(pid, nullptr, WNOHANG) == 0; ++k)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      if (::waitpid(pid, nullptr, WNOHANG) == 0) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, nullptr, 0);
      }
    }
    pids_.clear();
  }

 private:
  std::vector<std::string> Argv(int index) const {
    std::vector<std::string> argv = {"motionpipe"};
    if (args_.quiet) argv.insert(argv.end(), {"--log", "warn"});
    argv.insert(argv.end(),
                {"worker", "--coordinator", coordinator_, "--name",
                 "local-" + std::to_string(index), "--threads", std::to_string(threads_),
                 "--credit", std::to_string(args_.credit > 0 ? args_.credit : 2), "--heartbeat",
                 std::to_string(args_.heartbeat) + "s"});
    for (const std::string& dir : args_.plugin_dirs) argv.insert(argv.end(), {"--plugins", dir});
    return argv;
  }

  const RunArgs& args_;
  const std::string coordinator_;
  const int threads_;
  std::vector<pid_t> pids_;
  int restarts_ = 0;
};

// The job's progress on stdout: redrawn in place on a terminal, appended when it changed (at most
// every 5 s, 20 s for long pipelines) otherwise, nothing with --quiet.
class ProgressDisplay {
 public:
  explicit ProgressDisplay(bool quiet) : quiet_(quiet), tty_(::isatty(STDOUT_FILENO) && !quiet) {}

  bool tty() const { return tty_; }

  void Show(const wire::ControlReply& status) {
    if (quiet_) return;
    const bool compact = status.jobs(0).stages_size() > 12;
    const std::string block = FormatStatus(status, tty_, false, compact);
    if (tty_) {
      if (drawn_lines_ > 0) std::printf("\x1b[%dA", drawn_lines_);
      drawn_lines_ = 0;
      size_t start = 0;
      while (start < block.size()) {
        const size_t end = block.find('\n', start);
        std::printf("\x1b[K%s\n", block.substr(start, end - start).c_str());
        ++drawn_lines_;
        start = end + 1;
      }
      std::fflush(stdout);
      return;
    }
    const auto now = std::chrono::steady_clock::now();
    if (block != last_ && now - last_time_ > std::chrono::seconds(compact ? 20 : 5)) {
      std::fputs(block.c_str(), stdout);
      std::fflush(stdout);
      last_ = block;
      last_time_ = now;
    }
  }

  void Finish(const wire::ControlReply& status) {
    if (quiet_) return;
    const wire::JobStatus& job = status.jobs(0);
    if (!tty_) std::fputs(FormatStatus(status, false, false).c_str(), stdout);
    std::printf("job %lld %s in %.1f s; outputs in %s\n", static_cast<long long>(job.id()),
                job.state().c_str(), job.finished_unix() - job.created_unix(),
                job.output_dir().c_str());
  }

 private:
  const bool quiet_, tty_;
  int drawn_lines_ = 0;
  std::string last_;
  std::chrono::steady_clock::time_point last_time_ =
      std::chrono::steady_clock::now() - std::chrono::hours(1);
};

// Follows the job until it ends or `run` is interrupted; returns its final state ("interrupted"
// for the latter).
std::string Supervise(const std::string& control, int64_t job_id, const std::string& journal,
                      LocalWorkers* workers, ProgressDisplay* display) {
  while (true) {
    workers->RestartTheDead();
    auto status = StatusOf(control, job_id);
    if (status.ok() && status->jobs_size() == 1) {
      display->Show(*status);
      const std::string state = status->jobs(0).state();
      if (state != "running" && state != "pending") {
        display->Finish(*status);
        return state;
      }
    }
    if (g_run_signal.load()) {
      std::printf("interrupted: the job stays in %s; run the same command again to resume it\n",
                  journal.c_str());
      return "interrupted";
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(display->tty() ? 300 : 500));
  }
}

// `run`: a coordinator in this process and N worker processes on this machine; resumes an
// unfinished job of the same pipeline from the journal.
int RunPipeline(const RunArgs& a) {
  auto text = coordinator::ReadPipelineFile(a.pipeline);
  if (!text.ok()) return Fail(text.status());
  const coordinator::KindRegistry kinds = coordinator::CoordinatorKinds(a.plugin_dirs);
  auto spec = coordinator::ParsePipeline(*text, a.overrides, a.pipeline, kinds);
  if (!spec.ok()) return Fail(spec.status());
  if (a.print_resolved) {  // what the journal would keep: bases merged, overrides and vars applied
    std::printf("%s\n", nlohmann::ordered_json::parse(spec->resolved).dump(2).c_str());
    return kExitOk;
  }
  if (a.dry_run) return DryRun(*spec);
  if (a.quiet) SetLogLevel(std::max(LogLevel::kWarn, GetLogLevel()));
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  // A worker runs one task at a time (credit is how many it holds: the running one and those
  // prefetched behind it), so the default gives each worker's task its share of the cores.
  const int threads =
      a.threads > 0 ? a.threads : std::max(1, static_cast<int>(cores) / std::max(1, a.workers));
  if (threads * a.workers > static_cast<int>(cores)) {
    MP_LOG(kWarn, "run") << a.workers << " workers x " << threads << " threads oversubscribe "
                         << cores << " cores";
  }
  const std::string journal =
      a.journal.empty() ? spec->output_root + "/.motionpipe/journal.sqlite" : a.journal;
  auto resumed = UnfinishedJobOf(journal, spec->fingerprint);
  if (!resumed.ok()) return Fail(resumed.status());
  int64_t job_id = *resumed;

  LocalCoordinator coordinator;
  if (Status s = coordinator.Start(a, journal); !s.ok()) return Fail(s);
  std::signal(SIGINT, OnRunSignal);
  std::signal(SIGTERM, OnRunSignal);
  LocalWorkers workers(a, coordinator.worker_endpoint(), threads);
  workers.Start();
  if (job_id != 0) {
    if (!a.quiet)
      std::printf("resuming job %lld of %s from %s\n", static_cast<long long>(job_id),
                  a.pipeline.c_str(), journal.c_str());
  } else {
    wire::ControlRequest request;
    request.mutable_submit()->set_pipeline_yaml(*text);
    for (const std::string& override_ : a.overrides)
      request.mutable_submit()->add_overrides(override_);
    request.mutable_submit()->set_origin(a.pipeline);
    auto reply = Control(coordinator.control_endpoint(), request);
    if (!reply.ok() || !reply->ok())
      return Fail(reply.ok() ? InvalidArgument(reply->error()) : reply.status());
    job_id = reply->job_id();
  }
  ProgressDisplay display(a.quiet);
  const std::string state =
      Supervise(coordinator.control_endpoint(), job_id, journal, &workers, &display);
  workers.Stop();
  coordinator.Stop();
  return state == "succeeded" ? kExitOk : kExitFailure;
}

void AddRun(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "run", "Run a pipeline locally: a coordinator and N worker processes on this machine");
  static RunArgs a;
  cmd->add_option("pipeline", a.pipeline, "Pipeline YAML")->required()->check(CLI::ExistingFile);
  cmd->add_option("overrides", a.overrides, "Overrides key.sub=value");
  cmd->add_option("--workers,-w", a.workers, "Worker processes")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  cmd->add_option("--threads", a.threads,
                  "Threads per task (default, or 0: cores / workers, at least 1)")
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--credit", a.credit, "Tasks leased to a worker at once (default 2)")
      ->check(CLI::Range(0, 100000));
  cmd->add_option("--journal", a.journal,
                  "Journal file (default: <output_root>/.motionpipe/journal.sqlite)");
  cmd->add_option("--metrics", a.metrics,
                  "Serve the coordinator's /metrics here, e.g. 127.0.0.1:9100");
  cmd->add_option("--plugins", a.plugin_dirs, "Extra plugin directories");
  AddDurationOption(cmd, "--heartbeat", &a.heartbeat, "Heartbeat interval (default 1s)");
  cmd->add_flag("--quiet,-q", a.quiet,
                "No progress display, and only warnings and errors in the log");
  cmd->add_flag("--dry-run", a.dry_run,
                "Validate the pipeline and print its stages and task counts; start nothing");
  cmd->add_flag("--print-resolved", a.print_resolved,
                "Validate the pipeline and print it as the journal would keep it (a derived "
                "pipeline's bases merged, overrides, vars and targets applied), as JSON; start "
                "nothing");
  cmd->callback([exit_code] { *exit_code = RunPipeline(a); });
}

// ---- coordinator, worker -----------------------------------------------------------------------
void AddCoordinator(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "coordinator", "Run a coordinator (workers connect to it; submit jobs with `submit`)");
  static coordinator::CoordinatorOptions o;
  cmd->add_option("--bind", o.bind, "Endpoint for workers")->capture_default_str();
  cmd->add_option("--control", o.control,
                  "Endpoint for CLI requests (keep it on loopback unless you mean it)")
      ->capture_default_str();
  cmd->add_option("--journal", o.journal, "SQLite journal (WAL)")->capture_default_str();
  cmd->add_option("--metrics", o.metrics_bind, "Serve /metrics here, e.g. 127.0.0.1:9100");
  cmd->add_option("--liveness", o.liveness, "Missed heartbeats before a worker is lost")
      ->capture_default_str();
  AddDurationOption(cmd, "--heartbeat", &o.heartbeat_seconds, "Heartbeat interval (default 1s)");
  cmd->add_option("--curve-keys", o.curve_keys, "Key file of this coordinator: enables CurveZMQ")
      ->check(CLI::ExistingFile);
  cmd->add_option("--allow", o.allow_list, "Worker public keys admitted (one per line)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--plugins", o.plugin_dirs,
                  "Plugin directories whose stage kinds pipelines may use");
  cmd->callback([exit_code] {
    std::atomic<bool> stop{false};
    const Status s = coordinator::RunCoordinator(o, &stop, true);
    if (!s.ok()) *exit_code = Fail(s);
  });
}

void AddWorker(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("worker", "Run a worker that connects to a coordinator");
  static worker::WorkerOptions o;
  cmd->add_option("--coordinator,-c", o.coordinator, "Coordinator endpoint")->capture_default_str();
  cmd->add_option("--name", o.name, "Worker name (default host:pid)");
  cmd->add_option("--threads", o.threads, "Thread budget of one task (0: all cores)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--credit", o.credit, "Tasks leased at once")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  AddDurationOption(cmd, "--heartbeat", &o.heartbeat_seconds, "Heartbeat interval (default 1s)");
  cmd->add_option("--liveness", o.liveness, "Missed heartbeats before reconnecting")
      ->capture_default_str();
  AddDurationOption(cmd, "--drain-timeout", &o.drain_timeout_seconds,
                    "On SIGTERM, how long the running task may finish (default " +
                        std::to_string(static_cast<int>(o.drain_timeout_seconds)) + "s)");
  cmd->add_option("--plugins", o.plugin_dirs, "Extra plugin directories");
  cmd->add_option("--metrics", o.metrics_bind, "Serve /metrics here, e.g. 127.0.0.1:9101");
  cmd->add_option("--curve-keys", o.curve_keys, "This worker's key file: enables CurveZMQ")
      ->check(CLI::ExistingFile);
  cmd->add_option("--server-key", o.server_key,
                  "The coordinator's public key (40-char Z85) or key file");
  cmd->callback([exit_code] {
    // Before the worker's first thread: a model's task thread must not get a heap of its own.
    if (!worker::UseMainHeapOnly())
      MP_LOG(kInfo, "worker") << "glibc's arenas kept (MALLOC_ARENA_MAX or GLIBC_TUNABLES set, or "
                                 "glibc refused one heap): training steps may page-fault";
    std::atomic<bool> stop{false};
    worker::WorkerOptions options = o;
    if (options.threads == 0)
      options.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    const Status s = worker::RunWorker(options, &stop, true);
    if (!s.ok()) *exit_code = Fail(s);
  });
}

// ---- submit, status, wait, cancel: requests to a running coordinator ----------------------------
std::string& ControlEndpoint() {
  static std::string control = DefaultControlEndpoint();
  return control;
}

void AddControlOption(CLI::App* cmd) {
  cmd->add_option("--control", ControlEndpoint(),
                  "Coordinator control endpoint (or MOTIONPIPE_CONTROL)")
      ->capture_default_str();
}

struct SubmitArgs {
  std::string pipeline;
  std::vector<std::string> overrides;
};

int RunSubmit(const SubmitArgs& a) {
  auto text = coordinator::ReadPipelineFile(a.pipeline);
  if (!text.ok()) return Fail(text.status());
  wire::ControlRequest request;
  request.mutable_submit()->set_pipeline_yaml(*text);
  for (const std::string& o : a.overrides) request.mutable_submit()->add_overrides(o);
  request.mutable_submit()->set_origin(a.pipeline);
  auto reply = Control(ControlEndpoint(), request);
  if (!reply.ok()) return Fail(reply.status());
  if (!reply->ok()) return Fail(InvalidArgument(reply->error()));
  if (reply->job_id() == 0)
    std::printf("scheduled (recurring pipeline); see `motionpipe status`\n");
  else
    std::printf("%lld\n", static_cast<long long>(reply->job_id()));
  return kExitOk;
}

void AddSubmit(CLI::App& app, int* exit_code) {
  auto* cmd =
      app.add_subcommand("submit", "Submit a pipeline to a running coordinator; prints the job id");
  static SubmitArgs a;
  cmd->add_option("pipeline", a.pipeline, "Pipeline YAML")->required()->check(CLI::ExistingFile);
  cmd->add_option("overrides", a.overrides, "Overrides key.sub=value");
  AddControlOption(cmd);
  cmd->callback([exit_code] { *exit_code = RunSubmit(a); });
}

struct StatusArgs {
  int64_t job = 0;
  bool json = false, watch = false;
};

int RunStatus(const StatusArgs& a) {
  const bool tty = ::isatty(STDOUT_FILENO);
  do {
    auto reply = StatusOf(ControlEndpoint(), a.job);
    if (!reply.ok()) return Fail(reply.status());
    if (!reply->ok()) return Fail(NotFound(reply->error()));
    if (a.json) {
      std::puts(JsonOf(*reply).c_str());
    } else {
      if (reply->jobs_size() == 0) std::printf("no jobs\n");
      std::fputs(FormatStatus(*reply, tty, true).c_str(), stdout);
      if (reply->workers_size() == 0) std::printf("no workers connected\n");
    }
    std::fflush(stdout);
    if (a.watch) std::this_thread::sleep_for(std::chrono::seconds(1));
  } while (a.watch);
  return kExitOk;
}

void AddStatus(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "status", "Jobs, their stages (counts, throughput, ETA, failures) and workers");
  static StatusArgs a;
  cmd->add_option("job", a.job, "Job id (default: all)");
  AddControlOption(cmd);
  cmd->add_flag("--json", a.json, "Machine-readable output (every field, empty lists included)");
  cmd->add_flag("--watch", a.watch, "Refresh every second until interrupted");
  cmd->callback([exit_code] { *exit_code = RunStatus(a); });
}

struct WaitArgs {
  int64_t job = 0;
  double timeout = 0;
};

int RunWait(const WaitArgs& a) {
  const auto start = std::chrono::steady_clock::now();
  while (true) {
    auto reply = StatusOf(ControlEndpoint(), a.job);
    if (!reply.ok()) return Fail(reply.status());
    if (!reply->ok() || reply->jobs_size() != 1) return Fail(NotFound(reply->error()));
    const std::string state = reply->jobs(0).state();
    if (state != "running" && state != "pending") {
      std::printf("job %lld %s\n", static_cast<long long>(a.job), state.c_str());
      if (!reply->jobs(0).error().empty()) std::printf("%s\n", reply->jobs(0).error().c_str());
      return state == "succeeded" ? kExitOk : kExitFailure;
    }
    if (a.timeout > 0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >
            a.timeout) {
      std::printf("job %lld still %s after the timeout\n", static_cast<long long>(a.job),
                  state.c_str());
      return kExitFailure;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
  }
}

void AddWait(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "wait", "Wait for a job; exit 0 if it succeeded, 1 if it failed or was cancelled");
  static WaitArgs a;
  cmd->add_option("job", a.job, "Job id")->required();
  AddControlOption(cmd);
  AddDurationOption(cmd, "--timeout", &a.timeout,
                    "Give up after this long (exit 1; default never)");
  cmd->callback([exit_code] { *exit_code = RunWait(a); });
}

int RunCancel(int64_t job) {
  wire::ControlRequest request;
  request.mutable_cancel()->set_job_id(job);
  auto reply = Control(ControlEndpoint(), request);
  if (!reply.ok()) return Fail(reply.status());
  if (!reply->ok()) return Fail(FailedPrecondition(reply->error()));
  std::printf("job %lld cancelled\n", static_cast<long long>(job));
  return kExitOk;
}

void AddCancel(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("cancel", "Cancel a job");
  static int64_t job = 0;
  cmd->add_option("job", job, "Job id")->required();
  AddControlOption(cmd);
  cmd->callback([exit_code] { *exit_code = RunCancel(job); });
}

// ---- plugins, keys -----------------------------------------------------------------------------
int RunPluginsList(const std::vector<std::string>& dirs) {
  worker::PluginHost host;
  std::vector<std::string> searched = dirs;
  for (const std::string& d : worker::DefaultPluginDirs()) searched.push_back(d);
  for (const std::string& d : searched) host.LoadDirectory(d);
  std::printf("searched: ");
  for (size_t k = 0; k < searched.size(); ++k)
    std::printf("%s%s", k ? ", " : "", searched[k].c_str());
  std::printf("\n");
  for (const auto& p : host.plugins()) {
    std::printf("%s %s (%s)\n", p.name.c_str(), p.version.c_str(), p.path.c_str());
    for (const std::string& k : p.stage_kinds) std::printf("  stage kind %s\n", k.c_str());
    for (const std::string& k : p.objects) std::printf("  object %s\n", k.c_str());
  }
  for (const auto& problem : host.problems())
    std::printf("refused %s: %s\n", problem.path.c_str(), problem.message.c_str());
  return host.problems().empty() ? kExitOk : kExitFailure;
}

void AddPlugins(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("plugins", "Plugin libraries");
  cmd->require_subcommand(1);
  auto* list = cmd->add_subcommand(
      "list", "Load the plugins and list their stage kinds and objects (and any problems)");
  static std::vector<std::string> dirs;
  // --plugins as in run, coordinator and worker; --dir is the older name.
  list->add_option("--plugins,--dir", dirs, "Plugin directories (besides the defaults)");
  list->callback([exit_code] { *exit_code = RunPluginsList(dirs); });
}

int RunKeysGenerate(const std::string& out) {
  auto keys = net::GenerateCurveKeyPair();
  if (!keys.ok()) return Fail(keys.status());
  if (const Status s = WriteFileAtomic(out, net::FormatKeyFile(*keys)); !s.ok()) return Fail(s);
  ::chmod(out.c_str(), 0600);
  std::printf("%s\n", keys->public_key.c_str());
  return kExitOk;
}

void AddKeys(CLI::App& app, int* exit_code) {
  auto* cmd =
      app.add_subcommand("keys", "CurveZMQ keys for encrypted, authenticated worker connections");
  cmd->require_subcommand(1);
  auto* generate =
      cmd->add_subcommand("generate", "Write a new key pair (mode 600) and print the public key");
  static std::string out;
  generate->add_option("--out", out, "Key file to write")->required();
  generate->callback([exit_code] { *exit_code = RunKeysGenerate(out); });
}

}  // namespace

// Each command is an args struct, a run function returning the exit code, and an Add function
// that declares its options (CLI11 writes the parsed values into the static args).
void AddEngineCommands(CLI::App& app, int* exit_code) {
  AddRun(app, exit_code);
  AddCoordinator(app, exit_code);
  AddWorker(app, exit_code);
  AddSubmit(app, exit_code);
  AddStatus(app, exit_code);
  AddWait(app, exit_code);
  AddCancel(app, exit_code);
  AddPlugins(app, exit_code);
  AddKeys(app, exit_code);
}

}  // namespace motionpipe::cli
