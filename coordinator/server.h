// The coordinator process: the ROUTER socket workers connect to, the control socket the CLI talks
// to (submit, status, cancel, shutdown), the scheduler, the journal, heartbeats and /metrics.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "pipeline.h"

namespace motionpipe::coordinator {

struct CoordinatorOptions {
  std::string bind = "tcp://*:5555";             // workers connect here
  std::string control = "tcp://127.0.0.1:5556";  // CLI requests; loopback unless configured
  std::string journal = "motionpipe-journal.sqlite";
  std::string metrics_bind;  // "127.0.0.1:9100"; empty = no /metrics
  double heartbeat_seconds = 1.0;
  int liveness = 3;
  std::string curve_keys;                // the coordinator's key file: enables CurveZMQ for workers
  std::string allow_list;                // worker public keys admitted (required with curve_keys)
  std::vector<std::string> plugin_dirs;  // plugins whose stage kinds pipelines may use
  bool exit_when_idle = false;           // stop once every job has finished (motionpipe run)
  double flush_interval_seconds = 0.01;
};

// Runs the coordinator until `*stop`, a shutdown request, SIGTERM/SIGINT (when handle_signals), or
// (exit_when_idle) all jobs finished. `on_ready` (optional) is called with the bound worker and
// control endpoints once both sockets listen (for ephemeral ports "tcp://127.0.0.1:*").
Status RunCoordinator(
    const CoordinatorOptions& options, std::atomic<bool>* stop, bool handle_signals,
    const std::function<void(const std::string& workers, const std::string& control)>& on_ready =
        nullptr);

// The kinds a coordinator can plan: built-ins plus the stage kinds of plugins in `plugin_dirs` and
// the default plugin directories.
KindRegistry CoordinatorKinds(const std::vector<std::string>& plugin_dirs);

}  // namespace motionpipe::coordinator
