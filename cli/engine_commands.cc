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

int Fail(const Status& status) {
  std::cerr << "error: " << status.message() << "\n";
  return kExitFailure;
}

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

struct RunOptions {
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

int Run(const RunOptions& o) {
  auto text = ReadFile(o.pipeline);
  if (!text.ok()) return Fail(text.status());
  const coordinator::KindRegistry kinds = coordinator::CoordinatorKinds(o.plugin_dirs);
  auto spec = coordinator::ParsePipeline(*text, o.overrides, o.pipeline, kinds);
  if (!spec.ok()) return Fail(spec.status());
  if (o.dry_run) return DryRun(*spec);
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  // A worker runs one task at a time (credit is how many it holds: the running one and those
  // prefetched behind it), so the default gives each worker's task its share of the cores.
  const int threads =
      o.threads > 0 ? o.threads : std::max(1, static_cast<int>(cores) / std::max(1, o.workers));
  if (threads * o.workers > static_cast<int>(cores)) {
    MP_LOG(kWarn, "run") << o.workers << " workers x " << threads << " threads oversubscribe "
                         << cores << " cores";
  }
  const std::string journal =
      o.journal.empty() ? spec->output_root + "/.motionpipe/journal.sqlite" : o.journal;
  // An unfinished job of this very pipeline in the journal is resumed, not started again.
  int64_t job_id = 0;
  {
    std::error_code ec;
    std::filesystem::create_directories(std::filesystem::path(journal).parent_path(), ec);
    auto j = coordinator::Journal::Open(journal);
    if (!j.ok()) return Fail(j.status());
    auto unfinished = (*j)->LoadUnfinished();
    if (!unfinished.ok()) return Fail(unfinished.status());
    for (const auto& job : *unfinished) {
      if (job.fingerprint == spec->fingerprint) job_id = job.id;
    }
  }

  coordinator::CoordinatorOptions copts;
  copts.bind = "tcp://127.0.0.1:*";
  copts.control = "tcp://127.0.0.1:*";
  copts.journal = journal;
  copts.metrics_bind = o.metrics;
  copts.plugin_dirs = o.plugin_dirs;
  copts.heartbeat_seconds = o.heartbeat;
  std::atomic<bool> stop{false};
  std::string worker_endpoint, control_endpoint;
  std::atomic<bool> ready{false};
  Status coordinator_status;
  std::thread coordinator_thread([&] {
    coordinator_status = coordinator::RunCoordinator(
        copts, &stop, false, [&](const std::string& w, const std::string& c) {
          worker_endpoint = w;
          control_endpoint = c;
          ready = true;
        });
    ready = true;
  });
  while (!ready) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  if (!coordinator_status.ok() || worker_endpoint.empty()) {
    stop = true;
    coordinator_thread.join();
    return Fail(coordinator_status.ok() ? Internal("coordinator failed to start")
                                        : coordinator_status);
  }

  std::signal(SIGINT, OnRunSignal);
  std::signal(SIGTERM, OnRunSignal);
  const auto worker_args = [&](int index) {
    std::vector<std::string> args = {"motionpipe",    "worker",
                                     "--coordinator", worker_endpoint,
                                     "--name",        "local-" + std::to_string(index),
                                     "--threads",     std::to_string(threads),
                                     "--credit",      std::to_string(o.credit > 0 ? o.credit : 2),
                                     "--heartbeat",   std::to_string(o.heartbeat) + "s"};
    for (const std::string& dir : o.plugin_dirs) {
      args.push_back("--plugins");
      args.push_back(dir);
    }
    return args;
  };
  std::vector<pid_t> pids(static_cast<size_t>(o.workers));
  for (int k = 0; k < o.workers; ++k) pids[static_cast<size_t>(k)] = SpawnWorker(worker_args(k));

  if (job_id != 0) {
    if (!o.quiet)
      std::printf("resuming job %lld of %s from %s\n", static_cast<long long>(job_id),
                  o.pipeline.c_str(), journal.c_str());
  } else {
    wire::ControlRequest request;
    request.mutable_submit()->set_pipeline_yaml(*text);
    for (const std::string& ov : o.overrides) request.mutable_submit()->add_overrides(ov);
    request.mutable_submit()->set_origin(o.pipeline);
    auto reply = Control(control_endpoint, request);
    if (!reply.ok() || !reply->ok()) {
      stop = true;
      for (pid_t pid : pids) ::kill(pid, SIGTERM);
      for (pid_t pid : pids) ::waitpid(pid, nullptr, 0);
      coordinator_thread.join();
      return Fail(reply.ok() ? InvalidArgument(reply->error()) : reply.status());
    }
    job_id = reply->job_id();
  }

  const bool tty = ::isatty(STDOUT_FILENO) && !o.quiet;
  int drawn_lines = 0, restarts = 0;
  std::string final_state, last_plain;
  auto last_plain_time = std::chrono::steady_clock::now() - std::chrono::hours(1);
  while (true) {
    // Supervise the workers: one that died (a crashing task, OOM...) is started again.
    for (size_t k = 0; k < pids.size(); ++k) {
      int status = 0;
      if (pids[k] > 0 && ::waitpid(pids[k], &status, WNOHANG) == pids[k]) {
        if (restarts++ < 100) {
          MP_LOG(kWarn, "run") << "worker local-" << k << " exited ("
                               << (WIFSIGNALED(status)
                                       ? "signal " + std::to_string(WTERMSIG(status))
                                       : "code " + std::to_string(WEXITSTATUS(status)))
                               << "); restarting it";
          pids[k] = SpawnWorker(worker_args(static_cast<int>(k)));
        } else {
          pids[k] = -1;
        }
      }
    }
    auto status = StatusOf(control_endpoint, job_id);
    if (status.ok() && status->jobs_size() == 1) {
      const wire::JobStatus& job = status->jobs(0);
      if (tty) {
        const std::string text_block = FormatStatus(*status, true, false, job.stages_size() > 12);
        if (drawn_lines > 0) std::printf("\x1b[%dA", drawn_lines);
        drawn_lines = 0;
        size_t start = 0;
        while (start < text_block.size()) {
          const size_t end = text_block.find('\n', start);
          std::printf("\x1b[K%s\n", text_block.substr(start, end - start).c_str());
          ++drawn_lines;
          start = end + 1;
        }
        std::fflush(stdout);
      } else if (!o.quiet) {
        const std::string text_block = FormatStatus(*status, false, false, job.stages_size() > 12);
        const auto now = std::chrono::steady_clock::now();
        if (text_block != last_plain &&
            now - last_plain_time > std::chrono::seconds(job.stages_size() > 12 ? 20 : 5)) {
          std::fputs(text_block.c_str(), stdout);
          std::fflush(stdout);
          last_plain = text_block;
          last_plain_time = now;
        }
      }
      if (job.state() != "running" && job.state() != "pending") {
        final_state = job.state();
        if (!tty && !o.quiet) std::fputs(FormatStatus(*status, false, false).c_str(), stdout);
        if (!o.quiet) {
          std::printf("job %lld %s in %.1f s; outputs in %s\n", static_cast<long long>(job_id),
                      final_state.c_str(), job.finished_unix() - job.created_unix(),
                      job.output_dir().c_str());
        }
        break;
      }
    }
    if (g_run_signal.load()) {
      final_state = "interrupted";
      std::printf("interrupted: the job stays in %s; run the same command again to resume it\n",
                  journal.c_str());
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(tty ? 300 : 500));
  }
  for (pid_t pid : pids) {
    if (pid > 0) ::kill(pid, SIGTERM);
  }
  for (pid_t pid : pids) {
    if (pid <= 0) continue;
    for (int k = 0; k < 100 && ::waitpid(pid, nullptr, WNOHANG) == 0; ++k)
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (::waitpid(pid, nullptr, WNOHANG) == 0) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, nullptr, 0);
    }
  }
  stop = true;
  coordinator_thread.join();
  return final_state == "succeeded" ? kExitOk : kExitFailure;
}

}  // namespace

void AddEngineCommands(CLI::App& app, int* exit_code) {
  {  // run
    auto* cmd = app.add_subcommand(
        "run", "Run a pipeline locally: a coordinator and N worker processes on this machine");
    static RunOptions o;
    cmd->add_option("pipeline", o.pipeline, "Pipeline YAML")->required()->check(CLI::ExistingFile);
    cmd->add_option("overrides", o.overrides, "Overrides key.sub=value");
    cmd->add_option("--workers,-w", o.workers, "Worker processes")
        ->capture_default_str()
        ->check(CLI::Range(1, 256));
    cmd->add_option("--threads", o.threads,
                    "Threads per task (default: cores / workers, at least 1)");
    cmd->add_option("--credit", o.credit, "Tasks leased to a worker at once (default 2)");
    cmd->add_option("--journal", o.journal,
                    "Journal file (default: <output_root>/.motionpipe/journal.sqlite)");
    cmd->add_option("--metrics", o.metrics,
                    "Serve the coordinator's /metrics here, e.g. 127.0.0.1:9100");
    cmd->add_option("--plugins", o.plugin_dirs, "Extra plugin directories");
    AddDurationOption(cmd, "--heartbeat", &o.heartbeat, "Heartbeat interval (default 1s)");
    cmd->add_flag("--quiet,-q", o.quiet, "No progress display");
    cmd->add_flag("--dry-run", o.dry_run,
                  "Validate the pipeline and print its stages and task counts; start nothing");
    cmd->callback([exit_code] { *exit_code = Run(o); });
  }
  {  // coordinator
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
  {  // worker
    auto* cmd = app.add_subcommand("worker", "Run a worker that connects to a coordinator");
    static worker::WorkerOptions o;
    cmd->add_option("--coordinator,-c", o.coordinator, "Coordinator endpoint")
        ->capture_default_str();
    cmd->add_option("--name", o.name, "Worker name (default host:pid)");
    cmd->add_option("--threads", o.threads, "Thread budget of one task")
        ->capture_default_str()
        ->check(CLI::Range(1, 1024));
    cmd->add_option("--credit", o.credit, "Tasks leased at once")
        ->capture_default_str()
        ->check(CLI::Range(1, 100000));
    AddDurationOption(cmd, "--heartbeat", &o.heartbeat_seconds, "Heartbeat interval (default 1s)");
    cmd->add_option("--liveness", o.liveness, "Missed heartbeats before reconnecting")
        ->capture_default_str();
    AddDurationOption(cmd, "--drain-timeout", &o.drain_timeout_seconds,
                      "On SIGTERM, how long the running task may finish");
    cmd->add_option("--plugins", o.plugin_dirs, "Extra plugin directories");
    cmd->add_option("--metrics", o.metrics_bind, "Serve /metrics here, e.g. 127.0.0.1:9101");
    cmd->add_option("--curve-keys", o.curve_keys, "This worker's key file: enables CurveZMQ")
        ->check(CLI::ExistingFile);
    cmd->add_option("--server-key", o.server_key,
                    "The coordinator's public key (40-char Z85) or key file");
    cmd->callback([exit_code] {
      std::atomic<bool> stop{false};
      const Status s = worker::RunWorker(o, &stop, true);
      if (!s.ok()) *exit_code = Fail(s);
    });
  }
  static std::string control = DefaultControlEndpoint();
  {  // submit
    auto* cmd = app.add_subcommand("submit",
                                   "Submit a pipeline to a running coordinator; prints the job id");
    static std::string pipeline;
    static std::vector<std::string> overrides;
    cmd->add_option("pipeline", pipeline, "Pipeline YAML")->required()->check(CLI::ExistingFile);
    cmd->add_option("overrides", overrides, "Overrides key.sub=value");
    cmd->add_option("--control", control, "Coordinator control endpoint")->capture_default_str();
    cmd->callback([exit_code] {
      auto text = ReadFile(pipeline);
      if (!text.ok()) return void(*exit_code = Fail(text.status()));
      wire::ControlRequest request;
      request.mutable_submit()->set_pipeline_yaml(*text);
      for (const std::string& o : overrides) request.mutable_submit()->add_overrides(o);
      request.mutable_submit()->set_origin(pipeline);
      auto reply = Control(control, request);
      if (!reply.ok()) return void(*exit_code = Fail(reply.status()));
      if (!reply->ok()) return void(*exit_code = Fail(InvalidArgument(reply->error())));
      if (reply->job_id() == 0)
        std::printf("scheduled (recurring pipeline); see `motionpipe status`\n");
      else
        std::printf("%lld\n", static_cast<long long>(reply->job_id()));
    });
  }
  {  // status
    auto* cmd = app.add_subcommand(
        "status", "Jobs, their stages (counts, throughput, ETA, failures) and workers");
    static int64_t job = 0;
    static bool json = false, watch = false;
    cmd->add_option("job", job, "Job id (default: all)");
    cmd->add_option("--control", control, "Coordinator control endpoint")->capture_default_str();
    cmd->add_flag("--json", json, "Machine-readable output");
    cmd->add_flag("--watch", watch, "Refresh every second until interrupted");
    cmd->callback([exit_code] {
      const bool tty = ::isatty(STDOUT_FILENO);
      do {
        auto reply = StatusOf(control, job);
        if (!reply.ok()) return void(*exit_code = Fail(reply.status()));
        if (!reply->ok()) return void(*exit_code = Fail(NotFound(reply->error())));
        if (json)
          std::puts(JsonOf(*reply).c_str());
        else
          std::fputs(FormatStatus(*reply, tty, true).c_str(), stdout);
        std::fflush(stdout);
        if (watch) std::this_thread::sleep_for(std::chrono::seconds(1));
      } while (watch);
    });
  }
  {  // wait
    auto* cmd = app.add_subcommand(
        "wait", "Wait for a job; exit 0 if it succeeded, 1 if it failed or was cancelled");
    static int64_t job = 0;
    static double timeout = 0;
    cmd->add_option("job", job, "Job id")->required();
    cmd->add_option("--control", control, "Coordinator control endpoint")->capture_default_str();
    AddDurationOption(cmd, "--timeout", &timeout, "Give up after this long (exit 1)");
    cmd->callback([exit_code] {
      const auto start = std::chrono::steady_clock::now();
      while (true) {
        auto reply = StatusOf(control, job);
        if (!reply.ok()) return void(*exit_code = Fail(reply.status()));
        if (!reply->ok() || reply->jobs_size() != 1)
          return void(*exit_code = Fail(NotFound(reply->error())));
        const std::string state = reply->jobs(0).state();
        if (state != "running" && state != "pending") {
          std::printf("job %lld %s\n", static_cast<long long>(job), state.c_str());
          if (!reply->jobs(0).error().empty()) std::printf("%s\n", reply->jobs(0).error().c_str());
          *exit_code = state == "succeeded" ? kExitOk : kExitFailure;
          return;
        }
        if (timeout > 0 &&
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >
                timeout) {
          std::printf("job %lld still %s after the timeout\n", static_cast<long long>(job),
                      state.c_str());
          *exit_code = kExitFailure;
          return;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(250));
      }
    });
  }
  {  // cancel
    auto* cmd = app.add_subcommand("cancel", "Cancel a job");
    static int64_t job = 0;
    cmd->add_option("job", job, "Job id")->required();
    cmd->add_option("--control", control, "Coordinator control endpoint")->capture_default_str();
    cmd->callback([exit_code] {
      wire::ControlRequest request;
      request.mutable_cancel()->set_job_id(job);
      auto reply = Control(control, request);
      if (!reply.ok()) return void(*exit_code = Fail(reply.status()));
      if (!reply->ok()) return void(*exit_code = Fail(FailedPrecondition(reply->error())));
      std::printf("job %lld cancelled\n", static_cast<long long>(job));
    });
  }
  {  // plugins
    auto* cmd = app.add_subcommand("plugins", "Plugin libraries");
    cmd->require_subcommand(1);
    auto* list = cmd->add_subcommand(
        "list", "Load the plugins and list their stage kinds and objects (and any problems)");
    static std::vector<std::string> dirs;
    list->add_option("--dir", dirs, "Plugin directories (besides the defaults)");
    list->callback([exit_code] {
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
      if (!host.problems().empty()) *exit_code = kExitFailure;
    });
  }
  {  // keys
    auto* cmd =
        app.add_subcommand("keys", "CurveZMQ keys for encrypted, authenticated worker connections");
    cmd->require_subcommand(1);
    auto* generate =
        cmd->add_subcommand("generate", "Write a new key pair (mode 600) and print the public key");
    static std::string out;
    generate->add_option("--out", out, "Key file to write")->required();
    generate->callback([exit_code] {
      auto keys = net::GenerateCurveKeyPair();
      if (!keys.ok()) return void(*exit_code = Fail(keys.status()));
      if (const Status s = WriteFileAtomic(out, net::FormatKeyFile(*keys)); !s.ok())
        return void(*exit_code = Fail(s));
      ::chmod(out.c_str(), 0600);
      std::printf("%s\n", keys->public_key.c_str());
    });
  }
}

}  // namespace motionpipe::cli
