#include "control_client.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <zmq.hpp>

#include "motionpipe/net/protocol.h"

namespace motionpipe::cli {

std::string DefaultControlEndpoint() {
  const char* env = std::getenv("MOTIONPIPE_CONTROL");
  return env && *env ? env : "tcp://127.0.0.1:5556";
}

Result<wire::ControlReply> Control(const std::string& endpoint, const wire::ControlRequest& request,
                                   double timeout_seconds) {
  zmq::context_t context(1);
  zmq::socket_t socket(context, zmq::socket_type::dealer);
  socket.set(zmq::sockopt::linger, 0);
  try {
    socket.connect(endpoint);
  } catch (const zmq::error_t& e) {
    return InvalidArgument("bad control endpoint '" + endpoint + "': " + e.what());
  }
  if (!net::Send(socket, nullptr, net::MessageType::kControlRequest, request)) {
    return IoError("cannot send to the coordinator at " + endpoint);
  }
  zmq::pollitem_t item{socket.handle(), 0, ZMQ_POLLIN, 0};
  if (net::Poll(&item, 1, std::chrono::milliseconds(static_cast<int>(timeout_seconds * 1000))) <=
      0) {
    return IoError("no coordinator answered at " + endpoint + " within " +
                   std::to_string(static_cast<int>(timeout_seconds)) +
                   " s (is it running? set --control or MOTIONPIPE_CONTROL)");
  }
  std::vector<zmq::message_t> frames;
  net::ReceiveFrames(socket, &frames);
  net::Envelope envelope;
  if (net::DecodeFrames(frames, false, &envelope) != net::DropReason::kNone ||
      envelope.type != net::MessageType::kControlReply) {
    return DataLoss("malformed reply from " + endpoint);
  }
  wire::ControlReply reply;
  if (!net::ParseBody(envelope.body, &reply)) return DataLoss("undecodable reply from " + endpoint);
  return reply;
}

namespace {
std::string Duration(double seconds) {
  if (seconds < 0) return "?";
  char buffer[32];
  if (seconds < 90)
    std::snprintf(buffer, sizeof(buffer), "%.0fs", seconds);
  else if (seconds < 5400)
    std::snprintf(buffer, sizeof(buffer), "%.0fm%02.0fs", std::floor(seconds / 60),
                  std::fmod(seconds, 60));
  else
    std::snprintf(buffer, sizeof(buffer), "%.0fh%02.0fm", std::floor(seconds / 3600),
                  std::fmod(seconds / 60, 60));
  return buffer;
}
}  // namespace

std::string FormatStatus(const wire::ControlReply& reply, bool tty, bool show_workers,
                         bool compact) {
  std::string out;
  char line[512];
  for (const wire::JobStatus& job : reply.jobs()) {
    std::snprintf(line, sizeof(line), "job %lld %-20s %-10s %s\n", static_cast<long long>(job.id()),
                  job.name().c_str(), job.state().c_str(), job.output_dir().c_str());
    out += line;
    // The whole job: stages and tasks done, elapsed time and an ETA from the tasks' pace so far.
    int stages_done = 0, tasks_done = 0, tasks_total = 0, running = 0, waiting = 0;
    for (const wire::StageStatus& stage : job.stages()) {
      stages_done += stage.committed() == stage.total();
      waiting += stage.committed() == 0 && stage.running() == 0;
      tasks_done += stage.committed(), tasks_total += stage.total(), running += stage.running();
    }
    const double end =
        job.finished_unix() > 0 ? job.finished_unix() : static_cast<double>(std::time(nullptr));
    const double elapsed = job.created_unix() > 0 ? end - job.created_unix() : -1;
    const double eta = tasks_done > 0 && elapsed > 0 && tasks_done < tasks_total
                           ? elapsed * (tasks_total - tasks_done) / tasks_done
                           : -1;
    std::snprintf(line, sizeof(line),
                  "  progress: stages %d/%d done, tasks %d/%d, %d running; elapsed %s, ETA %s%s\n",
                  stages_done, job.stages_size(), tasks_done, tasks_total, running,
                  Duration(elapsed).c_str(), Duration(eta).c_str(),
                  eta >= 0 ? " (from the tasks' pace so far)" : "");
    out += line;
    for (const wire::StageStatus& stage : job.stages()) {
      // Compact: only the stages at work or in trouble (long pipelines such as the demo).
      if (compact && stage.running() == 0 && stage.failed() + stage.quarantined() == 0) continue;
      const double fraction =
          stage.total() > 0 ? static_cast<double>(stage.committed()) / stage.total() : 0;
      std::string bar;
      if (tty) {
        const int width = 24, filled = static_cast<int>(fraction * width + 0.5);
        bar = "[" + std::string(static_cast<size_t>(filled), '#') +
              std::string(static_cast<size_t>(width - filled), '.') + "] ";
      }
      std::snprintf(
          line, sizeof(line),
          "  %-18s %-16s %-9s %s%6d/%-6d running %-4d failed %-3d %8.1f tasks/s  ETA %s\n",
          stage.name().c_str(), stage.kind().c_str(), stage.state().c_str(), bar.c_str(),
          stage.committed(), stage.total(), stage.running(), stage.failed() + stage.quarantined(),
          stage.tasks_per_second(), Duration(stage.eta_seconds()).c_str());
      out += line;
      for (const std::string& failure : stage.failures()) out += "    ! " + failure + "\n";
    }
    if (!job.error().empty()) out += "  error: " + job.error() + "\n";
  }
  if (show_workers) {
    for (const wire::WorkerStatus& w : reply.workers()) {
      std::snprintf(line, sizeof(line),
                    "worker %-28s %-9s running %d/%d, %lld done, seen %.1fs ago\n", w.id().c_str(),
                    w.state().c_str(), w.running(), w.credit(),
                    static_cast<long long>(w.tasks_done()), w.last_seen_seconds());
      out += line;
    }
  }
  return out;
}

}  // namespace motionpipe::cli
