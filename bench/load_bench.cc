// A loaded coordinator (issue 17): N jobs of M no-op tasks queued at once (default 20 x 50,000 =
// 1,000,000 tasks). Prints the coordinator's memory per queued task, the latency of submit and of
// status while they are queued, and the dispatch rate of one worker then, against the same
// coordinator's rate with one job alone, measured in the same run.
//   load_bench [--jobs N] [--tasks-per-job M] [--dispatch-tasks K] [--motionpipe PATH]
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "../cli/control_client.h"
#include "bench_util.h"
#include "motionpipe/base/log.h"
#include "server.h"

namespace {

using Clock = std::chrono::steady_clock;
namespace mc = motionpipe::coordinator;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

// This process's resident memory (the coordinator runs in it), bytes.
double ResidentBytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::atof(line.c_str() + 6) * 1024.0;
  }
  return 0;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

class Coordinator {
 public:
  explicit Coordinator(const std::string& dir) : dir_(dir) {
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    mc::CoordinatorOptions options;
    options.bind = "tcp://127.0.0.1:*";
    options.control = "tcp://127.0.0.1:*";
    options.journal = dir + "/journal.sqlite";
    thread_ = std::thread([this, options] {
      (void)mc::RunCoordinator(options, &stop_, false,
                               [&](const std::string& w, const std::string& c) {
                                 workers_ = w;
                                 control_ = c;
                                 ready_ = true;
                               });
    });
    while (!ready_) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ~Coordinator() {
    for (pid_t pid : pids_) ::kill(pid, SIGTERM);
    for (pid_t pid : pids_) ::waitpid(pid, nullptr, 0);
    stop_ = true;
    thread_.join();
    std::filesystem::remove_all(dir_);
  }
  // Submits a job of `tasks` no-op tasks; its id, and the seconds the submit took.
  std::pair<int64_t, double> Submit(const std::string& name, int tasks) {
    motionpipe::wire::ControlRequest submit;
    submit.mutable_submit()->set_pipeline_yaml(
        "name: " + name + "\noutput_root: " + dir_ +
        "\nstages: {noop: {kind: noop, params: {tasks: " + std::to_string(tasks) + "}}}\n");
    const auto start = Clock::now();
    auto reply = motionpipe::cli::Control(control_, submit);
    const double seconds = Seconds(start);
    if (!reply.ok() || !reply->ok()) {
      std::fprintf(stderr, "load_bench: submit failed: %s\n",
                   reply.ok() ? reply->error().c_str() : reply.status().message().c_str());
      std::exit(1);
    }
    return {reply->job_id(), seconds};
  }
  // A status request (all jobs when job is 0); its reply and the seconds it took.
  std::pair<motionpipe::wire::ControlReply, double> Status(int64_t job = 0) {
    motionpipe::wire::ControlRequest status;
    status.mutable_status();
    if (job) status.mutable_status()->set_job_id(job);
    const auto start = Clock::now();
    auto reply = motionpipe::cli::Control(control_, status);
    const double seconds = Seconds(start);
    return {reply.ok() ? *reply : motionpipe::wire::ControlReply(), seconds};
  }
  void StartWorker(const std::string& binary, int credit) {
    pids_.push_back(motionpipe::bench::Spawn({binary, "worker", "--coordinator", workers_,
                                              "--credit", std::to_string(credit), "--name",
                                              "load-" + std::to_string(pids_.size())}));
    while (Status().first.workers_size() < static_cast<int>(pids_.size()))
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  // Tasks per second until `job` has `tasks` committed (from the moment this is called).
  double DispatchRate(int64_t job, int tasks) {
    const auto start = Clock::now();
    while (true) {
      const auto reply = Status(job).first;
      int committed = 0;
      if (reply.jobs_size() == 1) {
        for (const auto& s : reply.jobs(0).stages()) committed += s.committed();
      }
      if (committed >= tasks) return committed / Seconds(start);
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }

 private:
  std::string dir_, workers_, control_;
  std::atomic<bool> stop_{false}, ready_{false};
  std::thread thread_;
  std::vector<pid_t> pids_;
};

}  // namespace

int main(int argc, char** argv) {
  int jobs = 20, per_job = 50000, dispatch_tasks = 50000;
  std::string binary =
      (std::filesystem::path(argv[0]).parent_path().parent_path() / "cli" / "motionpipe").string();
  for (int k = 1; k < argc; ++k) {
    if (!std::strcmp(argv[k], "--jobs") && k + 1 < argc)
      jobs = std::atoi(argv[++k]);
    else if (!std::strcmp(argv[k], "--tasks-per-job") && k + 1 < argc)
      per_job = std::atoi(argv[++k]);
    else if (!std::strcmp(argv[k], "--dispatch-tasks") && k + 1 < argc)
      dispatch_tasks = std::atoi(argv[++k]);
    else if (!std::strcmp(argv[k], "--motionpipe") && k + 1 < argc)
      binary = argv[++k];
  }
  dispatch_tasks = std::min(dispatch_tasks, per_job);
  motionpipe::SetLogLevel(motionpipe::LogLevel::kError);
  ::setenv("MOTIONPIPE_LOG", "error", 1);
  const std::string dir = "/tmp/motionpipe_load_bench";
  std::printf("loaded coordinator: %d jobs x %d no-op tasks = %lld queued, journal on, %u cores\n",
              jobs, per_job, static_cast<long long>(jobs) * per_job,
              std::thread::hardware_concurrency());

  // The reference: one job alone, the same worker.
  double alone = 0;
  {
    Coordinator c(dir);
    const auto [job, seconds] = c.Submit("alone", dispatch_tasks);
    (void)seconds;
    c.StartWorker(binary, 256);
    alone = c.DispatchRate(job, dispatch_tasks);
  }

  Coordinator c(dir);
  const double before = ResidentBytes();
  std::vector<double> submits;
  std::vector<int64_t> ids;
  for (int j = 0; j < jobs; ++j) {
    const auto [id, seconds] = c.Submit("load" + std::to_string(j), per_job);
    ids.push_back(id);
    submits.push_back(seconds);
  }
  const double after = ResidentBytes();
  std::vector<double> all, one;
  for (int k = 0; k < 10; ++k) {
    all.push_back(c.Status().second);
    one.push_back(c.Status(ids.back()).second);
  }
  const double late_submit = c.Submit("late", 10).second;  // one more job on a loaded coordinator
  c.StartWorker(binary, 256);
  const double loaded = c.DispatchRate(ids.front(), dispatch_tasks);
  const double tasks = static_cast<double>(jobs) * per_job;
  std::printf("memory: %.0f MB for %.0f queued tasks, %.0f bytes per task\n",
              (after - before) / 1e6, tasks, (after - before) / tasks);
  std::printf(
      "submit of a %d-task job: median %.3f s, max %.3f s; a 10-task job when loaded: %.4f s\n",
      per_job, Median(submits), *std::max_element(submits.begin(), submits.end()), late_submit);
  std::printf("status of every job: median %.4f s; of one job: median %.4f s\n", Median(all),
              Median(one));
  std::printf(
      "dispatch, 1 worker, credit 256: %.0f tasks/s alone, %.0f tasks/s with %.0f queued "
      "(ratio %.2f)\n",
      alone, loaded, tasks, loaded / alone);
  return 0;
}
