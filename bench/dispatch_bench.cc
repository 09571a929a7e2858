// End-to-end dispatch of no-op tasks: motionpipe (coordinator with the SQLite journal on + worker
// processes) against Dask distributed on the same machine in the same run.
//   dispatch_bench [--tasks N] [--dask-tasks N] [--motionpipe PATH] [--no-dask]
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "../cli/control_client.h"
#include "bench_util.h"
#include "motionpipe/base/log.h"
#include "server.h"

namespace {

using Clock = std::chrono::steady_clock;

struct Figures {
  double tasks_per_second;
  double overhead_us;
};

Figures RunMotionpipe(const std::string& binary, int workers, int credit, int tasks) {
  namespace mc = motionpipe::coordinator;
  const std::string dir = "/tmp/motionpipe_dispatch_bench";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  mc::CoordinatorOptions options;
  options.bind = "tcp://127.0.0.1:*";
  options.control = "tcp://127.0.0.1:*";
  options.journal = dir + "/journal.sqlite";  // the journal stays on: the goal is with it
  std::atomic<bool> stop{false};
  std::string worker_endpoint, control;
  std::atomic<bool> ready{false};
  std::thread coordinator([&] {
    (void)mc::RunCoordinator(options, &stop, false,
                             [&](const std::string& w, const std::string& c) {
                               worker_endpoint = w;
                               control = c;
                               ready = true;
                             });
  });
  while (!ready) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  std::vector<pid_t> pids;
  for (int k = 0; k < workers; ++k) {
    pids.push_back(
        motionpipe::bench::Spawn({binary, "worker", "--coordinator", worker_endpoint, "--credit",
                                  std::to_string(credit), "--name", "bench-" + std::to_string(k)}));
  }
  motionpipe::wire::ControlRequest status;
  status.mutable_status();
  // Wait for the workers to register, so process start-up is not timed.
  while (true) {
    auto reply = motionpipe::cli::Control(control, status);
    if (reply.ok() && reply->workers_size() == workers) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  motionpipe::wire::ControlRequest submit;
  submit.mutable_submit()->set_pipeline_yaml(
      "name: bench\noutput_root: " + dir +
      "\nstages: {noop: {kind: noop, params: {tasks: " + std::to_string(tasks) + "}}}\n");
  const auto start = Clock::now();
  auto submitted = motionpipe::cli::Control(control, submit);
  double seconds = 0;
  if (submitted.ok() && submitted->ok()) {
    status.mutable_status()->set_job_id(submitted->job_id());
    while (true) {
      auto reply = motionpipe::cli::Control(control, status);
      if (reply.ok() && reply->jobs_size() == 1 && reply->jobs(0).state() != "running") break;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    seconds = std::chrono::duration<double>(Clock::now() - start).count();
  } else {
    std::fprintf(stderr, "submit failed\n");
  }
  for (pid_t pid : pids) ::kill(pid, SIGTERM);
  for (pid_t pid : pids) ::waitpid(pid, nullptr, 0);
  stop = true;
  coordinator.join();
  std::filesystem::remove_all(dir);
  return {tasks / seconds, seconds / tasks * 1e6};
}

double RunDask(const std::string& script, int workers, int tasks) {
  const std::string command = "/usr/bin/python3 " + script + " --workers " +
                              std::to_string(workers) + " --tasks " + std::to_string(tasks) +
                              " 2>/dev/null";
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return 0;
  char line[128] = {0};
  const bool read = std::fgets(line, sizeof(line), pipe) != nullptr;
  ::pclose(pipe);
  return read ? std::atof(line) : 0;
}

}  // namespace

int main(int argc, char** argv) {
  int tasks = 200000, dask_tasks = 5000;
  bool dask = true;
  std::string binary =
      (std::filesystem::path(argv[0]).parent_path().parent_path() / "cli" / "motionpipe").string();
  const std::string script = std::string(MOTIONPIPE_SOURCE_DIR) + "/bench/reference/dask_noop.py";
  for (int k = 1; k < argc; ++k) {
    if (!std::strcmp(argv[k], "--tasks") && k + 1 < argc)
      tasks = std::atoi(argv[++k]);
    else if (!std::strcmp(argv[k], "--dask-tasks") && k + 1 < argc)
      dask_tasks = std::atoi(argv[++k]);
    else if (!std::strcmp(argv[k], "--motionpipe") && k + 1 < argc)
      binary = argv[++k];
    else if (!std::strcmp(argv[k], "--no-dask"))
      dask = false;
  }
  motionpipe::SetLogLevel(motionpipe::LogLevel::kError);
  ::setenv("MOTIONPIPE_LOG", "error", 1);
  std::printf("no-op task dispatch, journal on, %d tasks (Dask: %d), this machine: %u cores\n",
              tasks, dask_tasks, std::thread::hardware_concurrency());
  double best = 0;
  for (int workers : {1, 2}) {
    for (int credit : {1, 256}) {
      const Figures f = RunMotionpipe(binary, workers, credit, credit == 1 ? tasks / 10 : tasks);
      std::printf("motionpipe %d worker(s), credit %3d: %9.0f tasks/s  (%6.1f us per task)\n",
                  workers, credit, f.tasks_per_second, f.overhead_us);
      if (credit == 256) best = f.tasks_per_second;  // this worker count's pipelined figure
    }
    if (dask) {
      const double d = RunDask(script, workers, dask_tasks);
      std::printf("dask       %d worker(s)           : %9.0f tasks/s\n", workers, d);
      if (d > 0)
        std::printf("ratio motionpipe / dask, %d worker(s), credit 256: %.0fx (goal >= 50x)\n",
                    workers, best / d);
    }
  }
  return 0;
}
