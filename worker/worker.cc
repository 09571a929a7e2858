#include "worker.h"

#include <malloc.h>
#include <prometheus/counter.h>
#include <prometheus/exposer.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <map>
#include <mutex>
#include <random>
#include <thread>
#include <zmq.hpp>

#include "executor.h"
#include "motionpipe.pb.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/log.h"
#include "motionpipe/net/protocol.h"
#include "motionpipe/net/security.h"
#include "plugin_host.h"

namespace motionpipe::worker {

namespace {

using Clock = std::chrono::steady_clock;
using net::MessageType;

std::atomic<int> g_signal{0};
extern "C" void OnSignal(int signal) { g_signal = signal; }

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

struct Metrics {
  std::shared_ptr<prometheus::Registry> registry = std::make_shared<prometheus::Registry>();
  prometheus::Family<prometheus::Counter>& tasks = prometheus::BuildCounter()
                                                       .Name("motionpipe_worker_tasks_total")
                                                       .Help("Tasks finished by outcome")
                                                       .Register(*registry);
  prometheus::Histogram& duration =
      prometheus::BuildHistogram()
          .Name("motionpipe_worker_task_duration_seconds")
          .Help("Time to run one task")
          .Register(*registry)
          .Add({}, prometheus::Histogram::BucketBoundaries{0.001, 0.01, 0.1, 1, 10, 60, 600, 3600});
  prometheus::Gauge& busy = prometheus::BuildGauge()
                                .Name("motionpipe_worker_busy")
                                .Help("1 while a task runs")
                                .Register(*registry)
                                .Add({});
  prometheus::Gauge& queued = prometheus::BuildGauge()
                                  .Name("motionpipe_worker_queued_tasks")
                                  .Help("Leased tasks waiting to run")
                                  .Register(*registry)
                                  .Add({});
  prometheus::Counter& bytes = prometheus::BuildCounter()
                                   .Name("motionpipe_worker_bytes_written_total")
                                   .Help("Bytes of task outputs written")
                                   .Register(*registry)
                                   .Add({});
  prometheus::Counter& reconnects = prometheus::BuildCounter()
                                        .Name("motionpipe_worker_reconnects_total")
                                        .Help("Reconnections to the coordinator")
                                        .Register(*registry)
                                        .Add({});
  prometheus::Counter& heartbeats_missed =
      prometheus::BuildCounter()
          .Name("motionpipe_worker_heartbeats_missed_total")
          .Help("Times the coordinator went silent for the liveness period")
          .Register(*registry)
          .Add({});
  prometheus::Family<prometheus::Counter>& dropped =
      prometheus::BuildCounter()
          .Name("motionpipe_worker_messages_dropped_total")
          .Help("Malformed or unexpected messages dropped, by reason")
          .Register(*registry);
  // Live values a running task reports (training losses, learning rate, steps): one series per
  // stage kind and metric name, both bounded sets.
  prometheus::Family<prometheus::Gauge>& task_values =
      prometheus::BuildGauge()
          .Name("motionpipe_worker_task_value")
          .Help("The latest value of a metric the running task reports")
          .Register(*registry);
};

struct Job {
  int64_t attempt_id;
  wire::TaskSpec spec;
  std::shared_ptr<std::atomic<int>> cancel;
};

// Tasks and results between the I/O thread and the executor thread.
struct Channel {
  std::mutex mutex;
  std::condition_variable ready;
  std::deque<Job> queue;
  std::deque<wire::TaskResult> results;
  std::map<int64_t, std::shared_ptr<std::atomic<int>>> cancels;  // queued and running attempts
  int64_t running = 0;  // attempt id of the running task, 0 if none
  bool stop = false;
};

class WorkerProcess {
 public:
  WorkerProcess(const WorkerOptions& options, ExecutorRegistry* registry, const PluginHost* plugins,
                Metrics* metrics)
      : options_(options), registry_(registry), plugins_(plugins), metrics_(metrics) {}

  Status Run(std::atomic<bool>* stop, bool handle_signals);

 private:
  void ExecutorLoop();
  void Connect();
  void SendReady();
  void Send(MessageType type, const google::protobuf::MessageLite& message);
  void HandleMessage(const net::Envelope& envelope);
  void FlushResults();
  void HandBackQueued();
  bool ReclaimQueued(int64_t attempt_id);

  const WorkerOptions& options_;
  ExecutorRegistry* registry_;
  const PluginHost* plugins_;
  Metrics* metrics_;
  zmq::context_t context_{1};
  std::unique_ptr<zmq::socket_t> dealer_;
  std::unique_ptr<zmq::socket_t> wake_rx_;  // executor -> I/O wake-ups (inproc PAIR)
  Channel channel_;
  std::string name_;
  int incarnation_ = 0;
  std::string nonce_;
  Clock::time_point last_received_, last_sent_;
  double backoff_ = 1.0;
  bool draining_ = false;
  net::CurveKeyPair keys_;
  std::string server_key_;
};

void WorkerProcess::ExecutorLoop() {
  zmq::socket_t wake(context_, zmq::socket_type::pair);
  wake.set(zmq::sockopt::linger, 0);
  wake.connect("inproc://worker-wake");
  while (true) {
    Job job;
    {
      std::unique_lock<std::mutex> lock(channel_.mutex);
      channel_.ready.wait(lock, [&] { return channel_.stop || !channel_.queue.empty(); });
      if (channel_.stop) return;
      job = std::move(channel_.queue.front());
      channel_.queue.pop_front();
      channel_.running = job.attempt_id;
    }
    metrics_->busy.Set(1);
    const auto started = Clock::now();
    wire::TaskResult result;
    result.set_attempt_id(job.attempt_id);
    StageExecutor* executor = registry_->Find(job.spec.kind());
    if (!executor) {
      result.set_outcome(wire::TaskResult::BAD_INPUT);
      result.set_message("this worker cannot run stage kind '" + job.spec.kind() + "'");
    } else if (job.cancel->load()) {
      result.set_outcome(wire::TaskResult::ERROR);
      result.set_message("cancelled before it started");
    } else {
      TaskContext ctx;
      ctx.spec = job.spec;
      try {
        ctx.params =
            nlohmann::json::parse(job.spec.params_json().empty() ? "{}" : job.spec.params_json());
      } catch (const nlohmann::json::exception& e) {
        ctx.params = nlohmann::json::object();
      }
      ctx.cancel = job.cancel.get();
      ctx.threads = job.spec.threads() > 0 ? job.spec.threads() : options_.threads;
      ctx.on_metric = [this, kind = job.spec.kind()](const std::string& name, double value) {
        metrics_->task_values.Add({{"kind", kind}, {"name", name}}).Set(value);
      };
      TaskReport report = RunTask(*executor, ctx);
      result.set_outcome(report.outcome == Outcome::kOk         ? wire::TaskResult::OK
                         : report.outcome == Outcome::kBadInput ? wire::TaskResult::BAD_INPUT
                                                                : wire::TaskResult::ERROR);
      result.set_message(report.message);
      for (const auto& [key, value] : report.metrics) (*result.mutable_metrics())[key] = value;
      // Durable before reported: the coordinator journals the commit of what is reported, so a
      // power loss must not leave a committed task with outputs that never reached the disk.
      if (report.outcome == Outcome::kOk) {
        if (const Status synced = SyncTree(job.spec.output_dir()); !synced.ok()) {
          result.set_outcome(wire::TaskResult::ERROR);
          result.set_message("outputs not durable: " + synced.message());
        }
      }
      if (result.outcome() == wire::TaskResult::OK) {
        for (wire::OutputFile& out : ScanOutputs(job.spec.output_dir())) {
          metrics_->bytes.Increment(static_cast<double>(out.bytes()));
          *result.add_outputs() = std::move(out);
        }
      }
    }
    const double seconds = Seconds(Clock::now() - started);
    result.set_seconds(seconds);
    metrics_->duration.Observe(seconds);
    metrics_->tasks.Add({{"outcome", wire::TaskResult::Outcome_Name(result.outcome())}})
        .Increment();
    metrics_->busy.Set(0);
    {
      std::lock_guard<std::mutex> lock(channel_.mutex);
      channel_.running = 0;
      channel_.cancels.erase(job.attempt_id);
      channel_.results.push_back(std::move(result));
    }
    wake.send(zmq::str_buffer("r"), zmq::send_flags::dontwait);
  }
}

void WorkerProcess::Connect() {
  dealer_ = std::make_unique<zmq::socket_t>(context_, zmq::socket_type::dealer);
  dealer_->set(zmq::sockopt::linger, 500);
  dealer_->set(zmq::sockopt::sndhwm, 100000);
  dealer_->set(zmq::sockopt::rcvhwm, 100000);
  // A new identity per connection: the coordinator sees a fresh worker, and whatever it thought the
  // old connection held was already re-queued when it went silent.
  // name#pid.nonce.incarnation: unique even when a restarted process gets the same name (and pid).
  dealer_->set(zmq::sockopt::routing_id, name_ + "#" + std::to_string(::getpid()) + "." + nonce_ +
                                             "." + std::to_string(++incarnation_));
  if (!keys_.secret_key.empty()) net::ConfigureCurveClient(*dealer_, keys_, server_key_);
  dealer_->connect(options_.coordinator);
  last_received_ = Clock::now();
  SendReady();
}

void WorkerProcess::SendReady() {
  wire::Ready ready;
  ready.set_worker_id(name_);
  for (const std::string& kind : registry_->Kinds()) ready.add_kinds(kind);
  for (const LoadedPlugin& p : plugins_->plugins()) {
    wire::PluginInfo* info = ready.add_plugins();
    info->set_name(p.name);
    info->set_version(p.version);
    info->set_path(p.path);
    for (const std::string& k : p.stage_kinds) info->add_kinds(k);
  }
  ready.set_threads(options_.threads);
  ready.set_credit(std::max(1, options_.credit));
  char host[256] = {0};
  ::gethostname(host, sizeof(host) - 1);
  ready.set_hostname(host);
  ready.set_pid(::getpid());
  ready.set_metrics_endpoint(options_.metrics_bind);
  Send(MessageType::kReady, ready);
}

void WorkerProcess::Send(MessageType type, const google::protobuf::MessageLite& message) {
  if (net::Send(*dealer_, nullptr, type, message)) last_sent_ = Clock::now();
}

void WorkerProcess::HandleMessage(const net::Envelope& envelope) {
  switch (envelope.type) {
    case MessageType::kHeartbeat:
      break;
    case MessageType::kAssign: {
      wire::Assign assign;
      if (!net::ParseBody(envelope.body, &assign)) {
        metrics_->dropped.Add({{"reason", "undecodable"}}).Increment();
        return;
      }
      if (draining_) {  // leased while we announced the drain: give it straight back
        wire::TaskResult back;
        back.set_attempt_id(assign.attempt_id());
        back.set_outcome(wire::TaskResult::HANDED_BACK);
        back.set_message("worker draining");
        Send(MessageType::kTaskResult, back);
        return;
      }
      auto cancel = std::make_shared<std::atomic<int>>(0);
      {
        std::lock_guard<std::mutex> lock(channel_.mutex);
        channel_.cancels[assign.attempt_id()] = cancel;
        channel_.queue.push_back({assign.attempt_id(), assign.task(), cancel});
        metrics_->queued.Set(static_cast<double>(channel_.queue.size()));
      }
      channel_.ready.notify_one();
      break;
    }
    case MessageType::kCancel: {
      wire::Cancel cancel;
      if (!net::ParseBody(envelope.body, &cancel)) return;
      if (cancel.only_if_queued()) {
        if (ReclaimQueued(cancel.attempt_id())) {
          wire::TaskResult back;
          back.set_attempt_id(cancel.attempt_id());
          back.set_outcome(wire::TaskResult::HANDED_BACK);
          back.set_message("reclaimed for an idle worker");
          Send(MessageType::kTaskResult, back);
        }
        break;
      }
      std::lock_guard<std::mutex> lock(channel_.mutex);
      if (const auto it = channel_.cancels.find(cancel.attempt_id()); it != channel_.cancels.end())
        it->second->store(1);
      break;
    }
    case MessageType::kDisconnect: {
      wire::Disconnect d;
      net::ParseBody(envelope.body, &d);
      MP_LOG(kWarn, "worker") << "coordinator asked us to reconnect: " << d.reason();
      metrics_->reconnects.Increment();
      HandBackQueued();
      Connect();
      break;
    }
    default:
      metrics_->dropped.Add({{"reason", "type"}}).Increment();
      MP_LOG(kWarn, "worker") << "dropped an unexpected " << net::MessageTypeName(envelope.type)
                              << " message";
  }
}

void WorkerProcess::FlushResults() {
  std::deque<wire::TaskResult> results;
  {
    std::lock_guard<std::mutex> lock(channel_.mutex);
    results.swap(channel_.results);
    metrics_->queued.Set(static_cast<double>(channel_.queue.size()));
  }
  for (const wire::TaskResult& result : results) Send(MessageType::kTaskResult, result);
}

// Takes a queued (not started) attempt out of the queue; false if it is running or unknown.
bool WorkerProcess::ReclaimQueued(int64_t attempt_id) {
  std::lock_guard<std::mutex> lock(channel_.mutex);
  for (auto it = channel_.queue.begin(); it != channel_.queue.end(); ++it) {
    if (it->attempt_id != attempt_id) continue;
    channel_.queue.erase(it);
    channel_.cancels.erase(attempt_id);
    metrics_->queued.Set(static_cast<double>(channel_.queue.size()));
    return true;
  }
  return false;
}

// Queued (not started) tasks go back to the coordinator without using their retry budget.
void WorkerProcess::HandBackQueued() {
  std::deque<Job> queued;
  {
    std::lock_guard<std::mutex> lock(channel_.mutex);
    queued.swap(channel_.queue);
    for (const Job& job : queued) channel_.cancels.erase(job.attempt_id);
  }
  for (const Job& job : queued) {
    wire::TaskResult back;
    back.set_attempt_id(job.attempt_id);
    back.set_outcome(wire::TaskResult::HANDED_BACK);
    back.set_message("worker draining or reconnecting");
    Send(MessageType::kTaskResult, back);
  }
}

Status WorkerProcess::Run(std::atomic<bool>* stop, bool handle_signals) {
  char host[256] = {0};
  ::gethostname(host, sizeof(host) - 1);
  name_ =
      options_.name.empty() ? std::string(host) + ":" + std::to_string(::getpid()) : options_.name;
  {
    std::random_device rd;
    char hex[17];
    std::snprintf(hex, sizeof(hex), "%08x%08x", rd(), rd());
    nonce_ = hex;
  }
  if (!options_.curve_keys.empty()) {
    MP_ASSIGN_OR_RETURN(keys_, net::LoadKeyFile(options_.curve_keys));
    if (keys_.secret_key.empty())
      return InvalidArgument(options_.curve_keys +
                             ": no secret-key (a worker needs its own key pair)");
    server_key_ = options_.server_key;
    if (server_key_.size() != 40) {  // a key file rather than the key itself
      MP_ASSIGN_OR_RETURN(const net::CurveKeyPair server, net::LoadKeyFile(options_.server_key));
      server_key_ = server.public_key;
    }
  }
  if (handle_signals) {
    std::signal(SIGTERM, OnSignal);
    std::signal(SIGINT, OnSignal);
  }
  // A write to a socket whose peer died must be an error, not this process's death: Gloo's
  // transport and c10d's TCPStore write without MSG_NOSIGNAL (Python ignores SIGPIPE for them), so
  // a gang rank writing to a killed peer was killed by SIGPIPE and took the gang's restart with it.
  std::signal(SIGPIPE, SIG_IGN);
  wake_rx_ = std::make_unique<zmq::socket_t>(context_, zmq::socket_type::pair);
  wake_rx_->set(zmq::sockopt::linger, 0);
  wake_rx_->bind("inproc://worker-wake");
  std::thread executor([this] { ExecutorLoop(); });
  Connect();
  MP_LOG(kInfo, "worker") << name_ << " connecting to " << options_.coordinator << " with "
                          << registry_->Kinds().size() << " stage kinds, " << options_.threads
                          << " thread(s), credit " << options_.credit;
  const double heartbeat = options_.heartbeat_seconds;
  Clock::time_point drain_started;
  std::vector<zmq::message_t> frames;
  while (true) {
    if (!draining_ && ((stop && stop->load()) || g_signal.load())) {
      draining_ = true;
      drain_started = Clock::now();
      MP_LOG(kInfo, "worker") << name_ << " draining (" << (g_signal ? "signal" : "stop requested")
                              << ")";
      wire::Drain drain;
      drain.set_reason("shutting down");
      Send(MessageType::kDrain, drain);
      HandBackQueued();
    }
    if (draining_) {
      bool idle;
      int64_t running;
      {
        std::lock_guard<std::mutex> lock(channel_.mutex);
        idle = channel_.running == 0 && channel_.queue.empty() && channel_.results.empty();
        running = channel_.running;
      }
      if (idle) break;
      if (running && Seconds(Clock::now() - drain_started) > options_.drain_timeout_seconds) {
        wire::TaskResult back;
        back.set_attempt_id(running);
        back.set_outcome(wire::TaskResult::HANDED_BACK);
        back.set_message("worker drained before the task finished");
        Send(MessageType::kTaskResult, back);
        MP_LOG(kWarn, "worker") << "handed back attempt " << running << " after the drain timeout";
        break;
      }
    }
    zmq::pollitem_t items[] = {{dealer_->handle(), 0, ZMQ_POLLIN, 0},
                               {wake_rx_->handle(), 0, ZMQ_POLLIN, 0}};
    net::Poll(items, 2,
              std::chrono::milliseconds(static_cast<int>(std::max(10.0, heartbeat * 250))));
    if (items[1].revents & ZMQ_POLLIN) {
      zmq::message_t m;
      while (wake_rx_->recv(m, zmq::recv_flags::dontwait)) {
      }
      FlushResults();
    }
    if (items[0].revents & ZMQ_POLLIN) {
      int budget = 1000;
      while (budget-- > 0 && net::ReceiveFrames(*dealer_, &frames)) {
        last_received_ = Clock::now();
        backoff_ = 1.0;
        net::Envelope envelope;
        const net::DropReason reason = net::DecodeFrames(frames, false, &envelope);
        if (reason != net::DropReason::kNone) {
          metrics_->dropped.Add({{"reason", net::DropReasonName(reason)}}).Increment();
          MP_LOG(kWarn, "worker") << "dropped a malformed message (" << net::DropReasonName(reason)
                                  << ")";
          continue;
        }
        HandleMessage(envelope);
      }
    }
    const auto now = Clock::now();
    if (Seconds(now - last_sent_) >= heartbeat) {
      wire::Heartbeat hb;
      hb.set_sent_unix_ms(std::chrono::duration_cast<std::chrono::milliseconds>(
                              std::chrono::system_clock::now().time_since_epoch())
                              .count());
      Send(MessageType::kHeartbeat, hb);
    }
    // A silent coordinator: reconnect (with backoff) under a new identity.
    if (Seconds(now - last_received_) > options_.liveness * heartbeat * backoff_) {
      metrics_->heartbeats_missed.Increment();
      metrics_->reconnects.Increment();
      MP_LOG(kWarn, "worker") << "coordinator silent for "
                              << static_cast<int>(Seconds(now - last_received_))
                              << " s; reconnecting";
      backoff_ = std::min(backoff_ * 2, options_.reconnect_max_seconds /
                                            std::max(1e-3, options_.liveness * heartbeat));
      HandBackQueued();
      Connect();
    }
  }
  FlushResults();
  wire::Disconnect bye;
  bye.set_reason("worker exiting");
  Send(MessageType::kDisconnect, bye);
  {
    std::lock_guard<std::mutex> lock(channel_.mutex);
    channel_.stop = true;
  }
  channel_.ready.notify_all();
  bool stuck;
  {
    std::lock_guard<std::mutex> lock(channel_.mutex);
    stuck = channel_.running != 0;
  }
  if (stuck) {
    // The running task ignored its cancel flag and was handed back: leave without it.
    MP_LOG(kWarn, "worker") << name_ << " exiting with a task still running (handed back)";
    dealer_->close();
    std::_Exit(0);
  }
  executor.join();
  dealer_.reset();
  wake_rx_.reset();
  MP_LOG(kInfo, "worker") << name_ << " stopped";
  return Status::Ok();
}

}  // namespace

bool UseMainHeapOnly() {
  // glibc's own settings win: MALLOC_ARENA_MAX, or glibc.malloc.arena_max in GLIBC_TUNABLES.
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  if (std::getenv("MALLOC_ARENA_MAX") != nullptr ||
      (tunables != nullptr && std::strstr(tunables, "glibc.malloc.arena_max") != nullptr))
    return false;
  return mallopt(M_ARENA_MAX, 1) == 1;
}

Status RunWorker(const WorkerOptions& options, std::atomic<bool>* stop, bool handle_signals) {
  PluginHost plugins;
  for (const std::string& dir : options.plugin_dirs) plugins.LoadDirectory(dir);
  for (const std::string& dir : DefaultPluginDirs()) plugins.LoadDirectory(dir);
  ExecutorRegistry registry;
  RegisterBuiltinExecutors(&registry, &plugins);
  plugins.RegisterExecutors(&registry);
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
  WorkerProcess process(options, &registry, &plugins, &metrics);
  return process.Run(stop, handle_signals);
}

}  // namespace motionpipe::worker
