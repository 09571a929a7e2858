#include "server.h"

#include <prometheus/counter.h>
#include <prometheus/exposer.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <optional>
#include <zmq.hpp>

#include "../worker/plugin_host.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/log.h"
#include "motionpipe/net/protocol.h"
#include "motionpipe/net/security.h"
#include "scheduler.h"

namespace motionpipe::coordinator {

namespace {

using SteadyClock = std::chrono::steady_clock;
using net::MessageType;

std::atomic<int> g_signal{0};
extern "C" void OnCoordinatorSignal(int signal) { g_signal = signal; }

struct Metrics {
  std::shared_ptr<prometheus::Registry> registry = std::make_shared<prometheus::Registry>();
  prometheus::Family<prometheus::Counter>& tasks =
      prometheus::BuildCounter()
          .Name("motionpipe_coordinator_tasks_total")
          .Help("Task events by outcome (committed, error, failed, lost, ...)")
          .Register(*registry);
  prometheus::Histogram& duration =
      prometheus::BuildHistogram()
          .Name("motionpipe_coordinator_task_duration_seconds")
          .Help("Task run time reported by workers")
          .Register(*registry)
          .Add({}, prometheus::Histogram::BucketBoundaries{0.001, 0.01, 0.1, 1, 10, 60, 600, 3600});
  prometheus::Gauge& queue = prometheus::BuildGauge()
                                 .Name("motionpipe_coordinator_queue_depth")
                                 .Help("Tasks waiting to be leased")
                                 .Register(*registry)
                                 .Add({});
  prometheus::Gauge& workers = prometheus::BuildGauge()
                                   .Name("motionpipe_coordinator_workers_alive")
                                   .Help("Connected workers")
                                   .Register(*registry)
                                   .Add({});
  prometheus::Counter& heartbeats_missed =
      prometheus::BuildCounter()
          .Name("motionpipe_coordinator_heartbeats_missed_total")
          .Help("Workers declared dead after missing their heartbeats")
          .Register(*registry)
          .Add({});
  prometheus::Counter& bytes = prometheus::BuildCounter()
                                   .Name("motionpipe_coordinator_bytes_written_total")
                                   .Help("Bytes of committed task outputs")
                                   .Register(*registry)
                                   .Add({});
  prometheus::Family<prometheus::Counter>& dropped =
      prometheus::BuildCounter()
          .Name("motionpipe_coordinator_messages_dropped_total")
          .Help("Malformed or unexpected messages dropped, by reason")
          .Register(*registry);
  prometheus::Family<prometheus::Gauge>& jobs = prometheus::BuildGauge()
                                                    .Name("motionpipe_coordinator_jobs")
                                                    .Help("Jobs by state")
                                                    .Register(*registry);
  prometheus::Counter& refused = prometheus::BuildCounter()
                                     .Name("motionpipe_coordinator_workers_refused_total")
                                     .Help("Workers refused by the CURVE allow-list")
                                     .Register(*registry)
                                     .Add({});
};

std::string BoundEndpoint(zmq::socket_t& socket) { return socket.get(zmq::sockopt::last_endpoint); }

class CoordinatorProcess {
 public:
  CoordinatorProcess(const CoordinatorOptions& options, Scheduler* scheduler, Metrics* metrics)
      : options_(options), scheduler_(scheduler), metrics_(metrics) {}

  Status Run(std::atomic<bool>* stop, bool handle_signals,
             const std::function<void(const std::string&, const std::string&)>& on_ready);

 private:
  void OnWorkerMessage(const net::Envelope& envelope);
  void OnControlMessage(const net::Envelope& envelope);
  void SendOutgoing();
  void Drop(net::DropReason reason, const char* socket);
  void UpdateMetrics();

  const CoordinatorOptions& options_;
  Scheduler* scheduler_;
  Metrics* metrics_;
  zmq::context_t context_{1};
  std::unique_ptr<zmq::socket_t> workers_, control_;
  std::unique_ptr<net::ZapAuthenticator> zap_;
  std::map<std::string, SteadyClock::time_point> last_sent_;
  bool shutdown_ = false;
  SchedulerCounters reported_;
  int64_t dropped_logged_ = 0;
  int64_t refused_seen_ = 0;
};

void CoordinatorProcess::Drop(net::DropReason reason, const char* socket) {
  metrics_->dropped.Add({{"reason", net::DropReasonName(reason)}}).Increment();
  // Garbage can come in floods: log the first few, then one line per thousand.
  if (++dropped_logged_ <= 5 || dropped_logged_ % 1000 == 0) {
    MP_LOG(kWarn, "coordinator") << "dropped a malformed message on the " << socket << " socket ("
                                 << net::DropReasonName(reason) << "); " << dropped_logged_
                                 << " so far";
  }
}

void CoordinatorProcess::OnWorkerMessage(const net::Envelope& envelope) {
  const std::string& identity = envelope.identity;
  switch (envelope.type) {
    case MessageType::kReady: {
      wire::Ready ready;
      if (!net::ParseBody(envelope.body, &ready))
        return Drop(net::DropReason::kUndecodable, "worker");
      scheduler_->OnReady(identity, ready);
      last_sent_[identity] = SteadyClock::time_point{};  // heartbeat it right away
      return;
    }
    case MessageType::kTaskResult: {
      wire::TaskResult result;
      if (!net::ParseBody(envelope.body, &result))
        return Drop(net::DropReason::kUndecodable, "worker");
      metrics_->duration.Observe(result.seconds());
      scheduler_->OnResult(identity, result);
      break;
    }
    case MessageType::kHeartbeat:
      scheduler_->OnSeen(identity);
      break;
    case MessageType::kDrain:
      scheduler_->OnDrain(identity);
      break;
    case MessageType::kDisconnect:
      scheduler_->OnDisconnect(identity);
      last_sent_.erase(identity);
      return;
    default:
      return Drop(net::DropReason::kType, "worker");
  }
  // A worker we do not know (we restarted, or declared it dead): ask it to register again.
  if (!scheduler_->KnowsWorker(identity)) {
    wire::Disconnect again;
    again.set_reason("unknown worker: reconnect and send READY");
    net::Send(*workers_, &identity, MessageType::kDisconnect, again);
  }
}

void CoordinatorProcess::OnControlMessage(const net::Envelope& envelope) {
  wire::ControlReply reply;
  wire::ControlRequest request;
  if (envelope.type != MessageType::kControlRequest || !net::ParseBody(envelope.body, &request)) {
    return Drop(envelope.type != MessageType::kControlRequest ? net::DropReason::kType
                                                              : net::DropReason::kUndecodable,
                "control");
  }
  switch (request.request_case()) {
    case wire::ControlRequest::kSubmit: {
      const auto& submit = request.submit();
      auto job = scheduler_->Submit(submit.pipeline_yaml(),
                                    {submit.overrides().begin(), submit.overrides().end()},
                                    submit.origin().empty() ? "pipeline" : submit.origin());
      reply.set_ok(job.ok());
      if (job.ok())
        reply.set_job_id(*job);
      else
        reply.set_error(job.status().message());
      break;
    }
    case wire::ControlRequest::kStatus: {
      reply.set_ok(true);
      for (auto& job : scheduler_->JobStatuses(request.status().job_id()))
        *reply.add_jobs() = std::move(job);
      for (auto& worker : scheduler_->WorkerStatuses()) *reply.add_workers() = std::move(worker);
      if (request.status().job_id() != 0 && reply.jobs_size() == 0) {
        reply.set_ok(false);
        reply.set_error("no job " + std::to_string(request.status().job_id()) +
                        " on this coordinator");
      }
      break;
    }
    case wire::ControlRequest::kCancel: {
      const Status s = scheduler_->Cancel(request.cancel().job_id());
      reply.set_ok(s.ok());
      reply.set_error(s.message());
      break;
    }
    case wire::ControlRequest::kShutdown:
      shutdown_ = true;
      reply.set_ok(true);
      break;
    default:
      reply.set_ok(false);
      reply.set_error("empty request");
  }
  net::Send(*control_, &envelope.identity, MessageType::kControlReply, reply);
}

void CoordinatorProcess::SendOutgoing() {
  const auto now = SteadyClock::now();
  for (const Outgoing& out : scheduler_->TakeOutgoing()) {
    bool sent = false;
    if (out.assign) sent = net::Send(*workers_, &out.identity, MessageType::kAssign, *out.assign);
    if (out.cancel) sent = net::Send(*workers_, &out.identity, MessageType::kCancel, *out.cancel);
    if (sent) last_sent_[out.identity] = now;
    // An assignment that cannot be delivered is recovered when the worker is declared lost.
  }
}

void CoordinatorProcess::UpdateMetrics() {
  const SchedulerCounters& c = scheduler_->counters();
  const auto add = [&](const char* outcome, int64_t now, int64_t before) {
    if (now > before)
      metrics_->tasks.Add({{"outcome", outcome}}).Increment(static_cast<double>(now - before));
  };
  add("committed", c.committed, reported_.committed);
  add("error", c.errors, reported_.errors);
  add("failed", c.failed, reported_.failed);
  add("lost", c.lost, reported_.lost);
  add("quarantined", c.quarantined, reported_.quarantined);
  add("handed_back", c.handed_back, reported_.handed_back);
  add("lease_expired", c.lease_expired, reported_.lease_expired);
  add("duplicate", c.duplicates, reported_.duplicates);
  if (c.bytes_committed > reported_.bytes_committed)
    metrics_->bytes.Increment(static_cast<double>(c.bytes_committed - reported_.bytes_committed));
  reported_ = c;
  metrics_->queue.Set(static_cast<double>(scheduler_->pending_tasks()));
  metrics_->workers.Set(static_cast<double>(scheduler_->live_workers()));
  std::map<std::string, int> jobs{
      {"running", 0}, {"succeeded", 0}, {"failed", 0}, {"cancelled", 0}};
  for (const auto& job : scheduler_->JobStatuses(0)) ++jobs[job.state()];
  for (const auto& [state, count] : jobs) metrics_->jobs.Add({{"state", state}}).Set(count);
}

Status CoordinatorProcess::Run(
    std::atomic<bool>* stop, bool handle_signals,
    const std::function<void(const std::string&, const std::string&)>& on_ready) {
  workers_ = std::make_unique<zmq::socket_t>(context_, zmq::socket_type::router);
  workers_->set(zmq::sockopt::linger, 0);
  workers_->set(zmq::sockopt::router_mandatory, 1);
  workers_->set(zmq::sockopt::sndhwm, 100000);
  workers_->set(zmq::sockopt::rcvhwm, 100000);
  workers_->set(zmq::sockopt::maxmsgsize, static_cast<int64_t>(net::kMaxFrameBytes) + 64);
  if (!options_.curve_keys.empty()) {
    MP_ASSIGN_OR_RETURN(const net::CurveKeyPair keys, net::LoadKeyFile(options_.curve_keys));
    if (keys.secret_key.empty())
      return InvalidArgument(options_.curve_keys + ": no secret-key line");
    if (options_.allow_list.empty())
      return InvalidArgument("CURVE needs an allow-list of worker public keys (--allow FILE)");
    MP_ASSIGN_OR_RETURN(std::set<std::string> allowed, net::LoadAllowList(options_.allow_list));
    zap_ = std::make_unique<net::ZapAuthenticator>(context_, std::move(allowed));
    net::ConfigureCurveServer(*workers_, keys);
    MP_LOG(kInfo, "coordinator") << "CurveZMQ on: workers must present a key from "
                                 << options_.allow_list;
  }
  control_ = std::make_unique<zmq::socket_t>(context_, zmq::socket_type::router);
  control_->set(zmq::sockopt::linger, 0);
  control_->set(zmq::sockopt::maxmsgsize, static_cast<int64_t>(net::kMaxFrameBytes) + 64);
  try {
    workers_->bind(options_.bind);
    control_->bind(options_.control);
  } catch (const zmq::error_t& e) {
    return InvalidArgument("cannot bind " + options_.bind + " / " + options_.control + ": " +
                           e.what());
  }
  const std::string worker_endpoint = BoundEndpoint(*workers_),
                    control_endpoint = BoundEndpoint(*control_);
  MP_LOG(kInfo, "coordinator") << "listening for workers on " << worker_endpoint << ", control on "
                               << control_endpoint;
  if (on_ready) on_ready(worker_endpoint, control_endpoint);
  if (handle_signals) {
    std::signal(SIGTERM, OnCoordinatorSignal);
    std::signal(SIGINT, OnCoordinatorSignal);
  }

  auto last_flush = SteadyClock::now(), last_tick = SteadyClock::now(),
       last_metrics = SteadyClock::now();
  std::vector<zmq::message_t> frames;
  const double heartbeat = options_.heartbeat_seconds;
  while (!(stop && stop->load()) && !g_signal.load() && !shutdown_) {
    zmq::pollitem_t items[] = {{workers_->handle(), 0, ZMQ_POLLIN, 0},
                               {control_->handle(), 0, ZMQ_POLLIN, 0}};
    const int timeout_ms =
        scheduler_->journal_backlog() > 0 ? 2 : static_cast<int>(std::max(5.0, heartbeat * 100));
    net::Poll(items, 2, std::chrono::milliseconds(timeout_ms));
    bool events = false;
    if (items[0].revents & ZMQ_POLLIN) {
      // Drain a bounded batch per turn so control requests and timers are never starved.
      for (int budget = 0; budget < 20000 && net::ReceiveFrames(*workers_, &frames); ++budget) {
        net::Envelope envelope;
        const net::DropReason reason = net::DecodeFrames(frames, true, &envelope);
        if (reason != net::DropReason::kNone) {
          Drop(reason, "worker");
          continue;
        }
        OnWorkerMessage(envelope);
        events = true;
      }
    }
    if (items[1].revents & ZMQ_POLLIN) {
      while (net::ReceiveFrames(*control_, &frames)) {
        net::Envelope envelope;
        const net::DropReason reason = net::DecodeFrames(frames, true, &envelope);
        if (reason != net::DropReason::kNone) {
          Drop(reason, "control");
          continue;
        }
        OnControlMessage(envelope);
        events = true;
      }
    }
    const auto now = SteadyClock::now();
    if (std::chrono::duration<double>(now - last_tick).count() >= heartbeat / 4) {
      last_tick = now;
      scheduler_->Tick();
      for (const std::string& lost : scheduler_->TakeLostWorkers()) {
        metrics_->heartbeats_missed.Increment();
        last_sent_.erase(lost);
      }
    } else if (events) {
      scheduler_->Dispatch();
    }
    SendOutgoing();
    if (std::chrono::duration<double>(now - last_flush).count() >=
            options_.flush_interval_seconds ||
        scheduler_->journal_backlog() > 20000) {
      if (const Status s = scheduler_->FlushJournal(); !s.ok()) {
        // The journal is the only memory of what was committed: going on without it would hand
        // out work whose commits a restart forgets. Stop; restarted on a writable disk, the
        // coordinator resumes every job from what the journal holds.
        MP_LOG(kError, "coordinator")
            << s.message() << "; stopping: the journal cannot record commits";
        UpdateMetrics();
        return IoError(s.message() +
                       "; the coordinator stopped rather than run on a journal it cannot write: "
                       "free or fix its disk, "
                       "then start it again to resume every job from the journal");
      }
      last_flush = now;
    }
    // Heartbeats: every worker hears from us at least once per interval.
    for (auto& [identity, sent] : last_sent_) {
      if (std::chrono::duration<double>(now - sent).count() >= heartbeat) {
        wire::Heartbeat hb;
        if (net::Send(*workers_, &identity, MessageType::kHeartbeat, hb)) sent = now;
      }
    }
    if (std::chrono::duration<double>(now - last_metrics).count() >= 0.5) {
      last_metrics = now;
      UpdateMetrics();
      if (zap_ && zap_->refused() > refused_seen_) {
        metrics_->refused.Increment(static_cast<double>(zap_->refused() - refused_seen_));
        refused_seen_ = zap_->refused();
      }
    }
    if (options_.exit_when_idle && scheduler_->AllJobsFinished()) break;
  }
  const Status flushed = scheduler_->FlushJournal();
  UpdateMetrics();
  if (!flushed.ok()) {
    MP_LOG(kError, "coordinator") << flushed.message();
    return IoError(flushed.message() +
                   "; the last commits are not in the journal: start the coordinator again on a "
                   "writable disk");
  }
  MP_LOG(kInfo, "coordinator") << "stopped";
  return Status::Ok();
}

}  // namespace

KindRegistry CoordinatorKinds(const std::vector<std::string>& plugin_dirs) {
  KindRegistry kinds = KindRegistry::WithBuiltins();
  worker::PluginHost host;
  for (const std::string& dir : plugin_dirs) host.LoadDirectory(dir);
  for (const std::string& dir : worker::DefaultPluginDirs()) host.LoadDirectory(dir);
  for (const auto& plugin : host.plugins()) {
    for (const std::string& kind : plugin.stage_kinds) kinds.AddGeneric(kind);
  }
  return kinds;
}

Status RunCoordinator(const CoordinatorOptions& options, std::atomic<bool>* stop,
                      bool handle_signals,
                      const std::function<void(const std::string&, const std::string&)>& on_ready) {
  std::error_code ec;
  const auto journal_dir = std::filesystem::path(options.journal).parent_path();
  if (!journal_dir.empty()) std::filesystem::create_directories(journal_dir, ec);
  // One coordinator per journal: a second one would resume the first one's running jobs and hand
  // their tasks to its own workers, two trainers writing one checkpoint directory.
  std::optional<FileLock> lock;
  if (options.journal != ":memory:") {
    auto held = FileLock::Acquire(options.journal + ".lock");
    if (!held.ok()) {
      if (held.status().code() != StatusCode::kFailedPrecondition) return held.status();
      return FailedPrecondition(
          "the journal " + options.journal +
          " is in use by another coordinator: " + held.status().message() +
          "; wait for it to stop, or give this one its own journal (--journal)");
    }
    lock.emplace(std::move(*held));
  }
  MP_ASSIGN_OR_RETURN(std::unique_ptr<Journal> journal, Journal::Open(options.journal));
  SystemClock clock;
  Scheduler scheduler(journal.get(), &clock, CoordinatorKinds(options.plugin_dirs),
                      {options.heartbeat_seconds, options.liveness});
  MP_RETURN_IF_ERROR(scheduler.Resume());
  Metrics metrics;
  std::unique_ptr<prometheus::Exposer> exposer;
  if (!options.metrics_bind.empty()) {
    try {
      exposer = std::make_unique<prometheus::Exposer>(options.metrics_bind);
    } catch (const std::exception& e) {
      return InvalidArgument("cannot serve /metrics on " + options.metrics_bind + ": " + e.what());
    }
    exposer->RegisterCollectable(metrics.registry);
  }
  CoordinatorProcess process(options, &scheduler, &metrics);
  return process.Run(stop, handle_signals, on_ready);
}

}  // namespace motionpipe::coordinator
