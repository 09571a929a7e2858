#include "scheduler.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "cron.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/base/log.h"

namespace motionpipe::coordinator {

namespace fs = std::filesystem;

double SystemClock::Now() const {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

Scheduler::Scheduler(Journal* journal, const Clock* clock, KindRegistry kinds,
                     SchedulerOptions options)
    : journal_(journal), clock_(clock), kinds_(std::move(kinds)), options_(options) {
  // Attempt ids stay unique across coordinator restarts (a block per run, from the journal), so a
  // late result from before a restart can never be mistaken for a new attempt.
  auto block = journal_->NextAttemptBlock();
  next_attempt_ = (block.ok() ? *block : static_cast<int64_t>(clock_->Now())) << 32;
}

Scheduler::Job* Scheduler::FindJob(int64_t id) {
  const auto it = jobs_.find(id);
  return it == jobs_.end() ? nullptr : &it->second;
}

std::string Scheduler::TaskDir(const Job& job, const Stage& stage, int task) const {
  const std::string stage_dir = job.output_dir + "/" + stage.spec.name;
  if (stage.spec.reduce && task == stage.spec.shards)
    return stage_dir + "/" + layout::kResultDirName;
  return layout::TaskDir(stage_dir, task);
}

std::string Scheduler::StagingDir(const Job& job, const Stage& stage, int task,
                                  int64_t attempt) const {
  return job.output_dir + "/" + stage.spec.name + "/.staging/" + std::to_string(task) +
         ".attempt-" + std::to_string(attempt);
}

void Scheduler::BuildStages(Job* job) {
  job->stages.clear();
  for (const StageSpec& spec : job->spec.stages) {
    Stage stage;
    stage.spec = spec;
    stage.tasks.resize(static_cast<size_t>(spec.shards + (spec.reduce ? 1 : 0)));
    job->stages.push_back(std::move(stage));
  }
}

Result<int64_t> Scheduler::CreateJob(const PipelineSpec& spec) {
  Job job;
  job.spec = spec;
  job.created = clock_->Now();
  job.state = "running";
  BuildStages(&job);
  StoredJob stored;
  stored.name = spec.name;
  stored.pipeline = spec.resolved;
  stored.fingerprint = spec.fingerprint;
  stored.state = job.state;
  stored.created = job.created;
  for (const Stage& stage : job.stages) {
    for (size_t t = 0; t < stage.tasks.size(); ++t) {
      StoredTask task;
      task.stage = stage.spec.name;
      task.index = static_cast<int>(t);
      stored.tasks.push_back(std::move(task));
    }
  }
  // The output directory needs the id, which the journal assigns: insert, then record the
  // directory.
  std::error_code ec;
  const std::string root = fs::absolute(spec.output_root, ec).lexically_normal().string();
  stored.output_dir = root;  // completed below
  MP_ASSIGN_OR_RETURN(const int64_t id, journal_->CreateJob(stored));
  job.id = id;
  job.output_dir = root + "/" + spec.name + "-" + std::to_string(id);
  // A journal numbers only its own jobs: a directory of this name that already holds files was made
  // by another journal (or one since deleted). Writing into it would overwrite that job's outputs
  // and let its trainers resume checkpoints of another pipeline.
  if (fs::exists(job.output_dir, ec) && !fs::is_empty(job.output_dir, ec)) {
    const std::string why = job.output_dir +
                            " already holds the outputs of a job this journal did not make (one "
                            "run with another --journal, or a deleted journal): move it away, "
                            "resume that job with its own journal, or give this pipeline another "
                            "name";
    journal_->UpdateJob(id, "failed", clock_->Now(), why);
    return FailedPrecondition(why);
  }
  // Durable, as every commit's directories are: a power loss must not take the job's directory.
  if (const Status made = MakeDirsDurable(job.output_dir); !made.ok())
    return IoError(job.output_dir + ": cannot create the job directory: " + made.message());
  auto& stored_job = jobs_[id] = std::move(job);
  for (size_t s = 0; s < stored_job.stages.size(); ++s) {
    for (size_t t = 0; t < stored_job.stages[s].tasks.size(); ++t)
      Enqueue(&stored_job, s, static_cast<int>(t));
  }
  MP_LOG(kInfo, "coordinator") << "job " << id << " '" << spec.name
                               << "': " << stored_job.stages.size() << " stage(s) -> "
                               << stored_job.output_dir;
  return id;
}

Result<int64_t> Scheduler::Submit(const std::string& yaml,
                                  const std::vector<std::string>& overrides,
                                  const std::string& origin, bool run_now) {
  MP_ASSIGN_OR_RETURN(const PipelineSpec spec, ParsePipeline(yaml, overrides, origin, kinds_));
  if (!spec.schedule.empty() && !run_now) {
    MP_ASSIGN_OR_RETURN(const CronSpec cron, ParseCron(spec.schedule));
    StoredSchedule schedule{0, spec.name, spec.resolved, spec.schedule,
                            NextFireTime(cron, static_cast<int64_t>(clock_->Now()))};
    MP_ASSIGN_OR_RETURN(schedule.id, journal_->AddSchedule(schedule));
    schedules_.push_back(schedule);
    MP_LOG(kInfo, "coordinator") << "scheduled '" << spec.name << "' (" << spec.schedule
                                 << "), next run at unix " << schedule.next_fire;
    return 0;
  }
  return CreateJob(spec);
}

Status Scheduler::Resume() {
  MP_ASSIGN_OR_RETURN(auto stored_jobs, journal_->LoadUnfinished());
  for (StoredJob& stored : stored_jobs) {
    auto spec =
        ParsePipeline(stored.pipeline, {}, "journal job " + std::to_string(stored.id), kinds_);
    Job job;
    job.id = stored.id;
    job.created = stored.created;
    job.output_dir = stored.output_dir + "/" + stored.name + "-" + std::to_string(stored.id);
    if (!spec.ok()) {
      journal_->UpdateJob(stored.id, "failed", clock_->Now(), spec.status().message());
      MP_LOG(kError, "coordinator")
          << "job " << stored.id << " cannot resume: " << spec.status().message();
      continue;
    }
    job.spec = *spec;
    job.state = "running";
    BuildStages(&job);
    std::map<std::pair<std::string, int>, const StoredTask*> by_key;
    for (const StoredTask& task : stored.tasks) by_key[{task.stage, task.index}] = &task;
    auto& live = jobs_[job.id] = std::move(job);
    int64_t committed = 0;
    for (size_t s = 0; s < live.stages.size(); ++s) {
      Stage& stage = live.stages[s];
      for (size_t t = 0; t < stage.tasks.size(); ++t) {
        const auto it = by_key.find({stage.spec.name, static_cast<int>(t)});
        if (it == by_key.end()) continue;
        Task& task = stage.tasks[t];
        task.state = it->second->state;
        task.errors = it->second->errors;
        task.lost = it->second->lost;
        task.message = it->second->message;
        task.outputs = it->second->outputs;
        if (task.state == TaskState::kCommitted) {
          ++stage.committed;
          ++committed;
        }
        if (task.state == TaskState::kFailed || task.state == TaskState::kQuarantined)
          ++stage.failed;
      }
      for (size_t t = 0; t < stage.tasks.size(); ++t) {
        if (stage.tasks[t].state == TaskState::kPending) Enqueue(&live, s, static_cast<int>(t));
      }
    }
    MP_LOG(kInfo, "coordinator") << "resumed job " << live.id << " '" << live.spec.name
                                 << "': " << committed << " task(s) already committed";
    for (size_t s = 0; s < live.stages.size(); ++s) StageProgress(&live, s);
  }
  MP_ASSIGN_OR_RETURN(schedules_, journal_->LoadSchedules());
  return journal_->Flush();
}

Status Scheduler::Cancel(int64_t job_id) {
  Job* job = FindJob(job_id);
  if (!job) return NotFound("no job " + std::to_string(job_id));
  if (job->state != "running" && job->state != "pending") {
    return FailedPrecondition("job " + std::to_string(job_id) + " is already " + job->state);
  }
  FinishJob(job, "cancelled", "cancelled by request");
  return journal_->Flush();
}

bool Scheduler::InputsDone(const Job& job, const Stage& stage) const {
  for (const std::string& input : stage.spec.inputs) {
    for (const Stage& other : job.stages) {
      if (other.spec.name == input && other.committed != static_cast<int>(other.tasks.size()))
        return false;
    }
  }
  return true;
}

bool Scheduler::StageRunnable(const Job& job, size_t stage) const {
  return job.state == "running" && InputsDone(job, job.stages[stage]);
}

void Scheduler::Enqueue(Job* job, size_t stage_index, int task_index) {
  Stage& stage = job->stages[stage_index];
  Task& task = stage.tasks[static_cast<size_t>(task_index)];
  if (task.state != TaskState::kPending || task.live_attempts > 0) return;
  const bool is_reduce = stage.spec.reduce && task_index == stage.spec.shards;
  if (task.not_before > clock_->Now() || (is_reduce && stage.committed < stage.spec.shards)) {
    stage.waiting.insert(task_index);
  } else {
    stage.waiting.erase(task_index);
    stage.ready.push_back(task_index);
  }
}

std::optional<int> Scheduler::TakeReady(Job* job, size_t stage_index) {
  Stage& stage = job->stages[stage_index];
  while (!stage.ready.empty()) {
    const int t = stage.ready.front();
    stage.ready.pop_front();
    const Task& task = stage.tasks[static_cast<size_t>(t)];
    if (task.state == TaskState::kPending && task.live_attempts == 0)
      return t;  // skip stale entries
  }
  return std::nullopt;
}

wire::TaskSpec Scheduler::MakeSpec(const Job& job, size_t stage_index, int task,
                                   int64_t attempt) const {
  const Stage& stage = job.stages[stage_index];
  wire::TaskSpec spec;
  spec.set_job_id(job.id);
  spec.set_job_name(job.spec.name);
  spec.set_stage(stage.spec.name);
  spec.set_kind(stage.spec.kind);
  spec.set_index(task);
  spec.set_count(stage.spec.shards);
  spec.set_reduce(stage.spec.reduce && task == stage.spec.shards);
  spec.set_params_json(stage.spec.params.dump());
  spec.set_output_dir(StagingDir(job, stage, task, attempt));
  // A stage's own params.seed (seed replicates set it) overrides the pipeline's.
  const auto& params = stage.spec.params;
  spec.set_seed(params.contains("seed") && params["seed"].is_number_unsigned()
                    ? params["seed"].get<uint64_t>()
                    : job.spec.seed);
  spec.set_threads(stage.spec.threads);
  for (const std::string& input : stage.spec.inputs) {
    for (const Stage& other : job.stages) {
      if (other.spec.name != input) continue;
      wire::StageInput* in = spec.add_inputs();
      in->set_stage(input);
      for (int t = 0; t < other.spec.shards; ++t) in->add_dirs(TaskDir(job, other, t));
      if (other.spec.reduce) in->set_result_dir(TaskDir(job, other, other.spec.shards));
    }
  }
  if (spec.reduce()) {
    for (int t = 0; t < stage.spec.shards; ++t) spec.add_shard_dirs(TaskDir(job, stage, t));
  }
  const Task& state = stage.tasks[static_cast<size_t>(task)];
  spec.set_attempt(state.errors + state.lost);
  spec.set_world_size(stage.spec.world_size);
  spec.set_state_dir(job.output_dir + "/" + stage.spec.name + "/state");
  return spec;
}

void Scheduler::Assign(Worker* worker, Job* job, size_t stage_index, int task_index,
                       const std::string& rendezvous) {
  Stage& stage = job->stages[stage_index];
  Task& task = stage.tasks[static_cast<size_t>(task_index)];
  const int64_t id = next_attempt_++;
  const double now = clock_->Now();
  attempts_[id] = {id,
                   job->id,
                   stage_index,
                   task_index,
                   worker->identity,
                   now,
                   now + stage.spec.timeout_seconds,
                   false};
  worker->attempts.insert(id);
  ++task.live_attempts;
  ++stage.running;
  stage.started = true;
  Outgoing out;
  out.identity = worker->identity;
  out.assign.emplace();
  out.assign->set_attempt_id(id);
  *out.assign->mutable_task() = MakeSpec(*job, stage_index, task_index, id);
  out.assign->mutable_task()->set_rendezvous(rendezvous);
  out.assign->set_lease_ms(static_cast<int64_t>(stage.spec.timeout_seconds * 1000));
  outgoing_.push_back(std::move(out));
}

void Scheduler::DispatchGangs() {
  const double now = clock_->Now();
  for (auto& [id, job] : jobs_) {
    if (job.state != "running") continue;
    for (size_t s = 0; s < job.stages.size(); ++s) {
      Stage& stage = job.stages[s];
      if (!stage.gang() || !StageRunnable(job, s) || stage.running > 0) continue;
      // Every rank must be pending, idle and past its backoff.
      bool ready = stage.committed == 0;
      for (const Task& task : stage.tasks) {
        ready = ready && task.state == TaskState::kPending && task.live_attempts == 0 &&
                task.not_before <= now;
      }
      if (!ready) continue;
      std::vector<Worker*> free;
      for (auto& [identity, worker] : workers_) {
        const int credit = std::max(1, worker.ready.credit());
        if (!worker.draining && worker.kinds.count(stage.spec.kind) &&
            static_cast<int>(worker.attempts.size()) < credit) {
          free.push_back(&worker);
        }
      }
      if (static_cast<int>(free.size()) < stage.spec.world_size) continue;
      // Idle workers first, so that ranks do not share a busy machine's threads.
      std::stable_sort(free.begin(), free.end(), [](const Worker* a, const Worker* b) {
        return a->attempts.size() < b->attempts.size();
      });
      const std::string rendezvous = job.output_dir + "/" + stage.spec.name + "/.rendezvous/gang-" +
                                     std::to_string(next_attempt_);
      std::error_code ec;
      fs::create_directories(fs::path(rendezvous).parent_path(), ec);
      for (int rank = 0; rank < stage.spec.world_size; ++rank)
        Assign(free[static_cast<size_t>(rank)], &job, s, rank, rendezvous);
      MP_LOG(kInfo, "coordinator") << "job " << job.id << " stage '" << stage.spec.name
                                   << "': gang of " << stage.spec.world_size << " ranks started";
    }
  }
}

void Scheduler::StopGang(Job* job, size_t stage_index, int failed_rank, const std::string& why) {
  Stage& stage = job->stages[stage_index];
  std::vector<int64_t> siblings;
  for (const auto& [id, attempt] : attempts_) {
    if (attempt.job == job->id && attempt.stage == stage_index && attempt.task != failed_rank &&
        !attempt.expired)
      siblings.push_back(id);
  }
  for (const int64_t id : siblings) {
    const Attempt attempt = attempts_[id];
    Outgoing out;
    out.identity = attempt.identity;
    out.cancel.emplace();
    out.cancel->set_attempt_id(id);
    out.cancel->set_reason("gang stopped: " + why);
    outgoing_.push_back(std::move(out));
    ReleaseAttempt(id);
    std::error_code ec;
    fs::remove_all(StagingDir(*job, stage, attempt.task, id), ec);
  }
  if (stage.committed > 0 && job->state == "running") {
    FinishJob(job, "failed",
              "stage '" + stage.spec.name + "': rank " + std::to_string(failed_rank) +
                  " failed after other ranks finished: " + why);
    return;
  }
  for (int rank = 0; rank < static_cast<int>(stage.tasks.size()); ++rank) {
    if (rank != failed_rank) Enqueue(job, stage_index, rank);
  }
  if (!siblings.empty()) {
    MP_LOG(kWarn, "coordinator") << "job " << job->id << " stage '" << stage.spec.name
                                 << "': gang stopped (" << why
                                 << "); it restarts from its last checkpoint when "
                                 << stage.spec.world_size << " workers are free";
  }
}

bool Scheduler::AssignOne(Worker* worker) {
  for (auto& [id, job] : jobs_) {
    if (job.state != "running") continue;
    for (size_t s = 0; s < job.stages.size(); ++s) {
      Stage& stage = job.stages[s];
      if (stage.gang() || stage.ready.empty() || !worker->kinds.count(stage.spec.kind) ||
          !StageRunnable(job, s))
        continue;
      if (const auto task = TakeReady(&job, s)) {
        Assign(worker, &job, s, *task);
        return true;
      }
    }
  }
  return false;
}

void Scheduler::Dispatch() {
  DispatchGangs();
  // Idle workers first, one task each, so that a task handed back for an idle worker goes to it
  // and not back to the busy worker that held it; then every worker up to its credit.
  for (auto& [identity, worker] : workers_) {
    if (!worker.draining && worker.attempts.empty()) AssignOne(&worker);
  }
  for (auto& [identity, worker] : workers_) {
    const int credit = std::max(1, worker.ready.credit());
    while (!worker.draining && static_cast<int>(worker.attempts.size()) < credit &&
           AssignOne(&worker)) {
    }
  }
  ReclaimForIdleWorkers();
}

void Scheduler::ReclaimForIdleWorkers() {
  bool any_idle = false;
  for (const auto& [identity, worker] : workers_)
    any_idle = any_idle || (!worker.draining && worker.attempts.empty());
  if (!any_idle) return;  // the common case, kept O(workers)
  const double now = clock_->Now();
  int pending = 0;  // reclaims asked for and not yet answered
  for (const auto& [id, attempt] : attempts_) pending += attempt.reclaiming;
  for (auto& [identity, idle] : workers_) {
    if (idle.draining || !idle.attempts.empty()) continue;
    if (pending > 0) {  // an earlier reclaim is on its way to an idle worker
      --pending;
      continue;
    }
    // A worker runs its tasks one at a time in lease order: every attempt of a worker but its
    // oldest is queued. Take the newest one that has waited long enough.
    Attempt* best = nullptr;
    for (auto& [other_identity, busy] : workers_) {
      if (other_identity == identity || busy.attempts.size() < 2) continue;
      const int64_t running = *busy.attempts.begin();
      for (const int64_t id : busy.attempts) {
        Attempt& a = attempts_.at(id);
        if (id == running || a.reclaiming || a.expired ||
            now - a.started < options_.reclaim_after_seconds)
          continue;
        const Job* job = FindJob(a.job);
        if (!job || job->state != "running") continue;
        const Stage& stage = job->stages[a.stage];
        if (stage.gang() || !idle.kinds.count(stage.spec.kind)) continue;
        if (!best || a.id > best->id) best = &a;
      }
    }
    if (!best) continue;
    best->reclaiming = true;
    Outgoing out;
    out.identity = best->identity;
    out.cancel.emplace();
    out.cancel->set_attempt_id(best->id);
    out.cancel->set_only_if_queued(true);
    out.cancel->set_reason("reclaimed for idle worker " + identity);
    outgoing_.push_back(std::move(out));
  }
}

void Scheduler::ReleaseAttempt(int64_t attempt_id) {
  const auto it = attempts_.find(attempt_id);
  if (it == attempts_.end()) return;
  const Attempt& a = it->second;
  if (const auto w = workers_.find(a.identity); w != workers_.end())
    w->second.attempts.erase(attempt_id);
  if (Job* job = FindJob(a.job)) {
    Stage& stage = job->stages[a.stage];
    Task& task = stage.tasks[static_cast<size_t>(a.task)];
    if (!a.expired) {
      --task.live_attempts;
      --stage.running;
    }
  }
  attempts_.erase(it);
}

void Scheduler::OnReady(const std::string& identity, const wire::Ready& ready) {
  // READY again from a known connection means a new session: whatever it held is lost.
  if (workers_.count(identity)) DropWorker(identity, "re-registered");
  Worker& worker = workers_[identity];
  worker.identity = identity;
  worker.ready = ready;
  worker.kinds = std::set<std::string>(ready.kinds().begin(), ready.kinds().end());
  worker.last_seen = clock_->Now();
  worker.draining = false;
  MP_LOG(kInfo, "coordinator") << "worker " << ready.worker_id() << " ready: " << ready.kinds_size()
                               << " kinds, " << ready.threads() << " thread(s), credit "
                               << ready.credit();
}

void Scheduler::OnSeen(const std::string& identity) {
  if (const auto it = workers_.find(identity); it != workers_.end())
    it->second.last_seen = clock_->Now();
}

void Scheduler::OnDrain(const std::string& identity) {
  if (const auto it = workers_.find(identity); it != workers_.end()) {
    it->second.draining = true;
    MP_LOG(kInfo, "coordinator") << "worker " << it->second.ready.worker_id() << " is draining";
  }
}

void Scheduler::OnDisconnect(const std::string& identity) { DropWorker(identity, "disconnected"); }

void Scheduler::DropWorker(const std::string& identity, const std::string& reason) {
  const auto it = workers_.find(identity);
  if (it == workers_.end()) return;
  const std::string name = it->second.ready.worker_id();
  const std::set<int64_t> held = it->second.attempts;
  for (int64_t attempt_id : held) {
    const auto a = attempts_.find(attempt_id);
    if (a == attempts_.end()) continue;
    const Attempt attempt = a->second;
    ReleaseAttempt(attempt_id);
    if (attempt.expired) continue;
    if (Job* job = FindJob(attempt.job)) {
      TaskLost(job, attempt.stage, attempt.task,
               "worker " + name + " " + reason + " while running it");
    }
  }
  workers_.erase(it);
  ++counters_.workers_lost;
  // A worker that said goodbye holding nothing (a drained or stopped worker, `run` at its end) is
  // routine; one that took tasks with it, or stopped answering, is worth a warning.
  if (held.empty() && reason == "disconnected") {
    MP_LOG(kInfo, "coordinator") << "worker " << name << " disconnected";
    return;
  }
  MP_LOG(kWarn, "coordinator") << "worker " << name << " " << reason << "; " << held.size()
                               << " task(s) re-queued";
}

void Scheduler::TaskLost(Job* job, size_t stage_index, int task_index, const std::string& message) {
  Stage& stage = job->stages[stage_index];
  Task& task = stage.tasks[static_cast<size_t>(task_index)];
  if (task.state != TaskState::kPending) return;
  ++task.lost;
  ++counters_.lost;
  task.message = message;
  if (task.lost >= stage.spec.poison_threshold) {
    task.state = TaskState::kQuarantined;
    ++stage.failed;
    ++counters_.quarantined;
    const std::string report = "task " + std::to_string(task_index) +
                               " quarantined: it was running when " + std::to_string(task.lost) +
                               " workers died (poison); last: " + message;
    stage.failures.push_back(report);
    journal_->UpdateTask(job->id, stage.spec.name, task_index, task.state, task.errors, task.lost,
                         report);
    FinishJob(job, "failed", "stage '" + stage.spec.name + "': " + report);
    return;
  }
  journal_->UpdateTask(job->id, stage.spec.name, task_index, task.state, task.errors, task.lost,
                       message);
  Enqueue(job, stage_index, task_index);
  if (stage.gang())
    StopGang(job, stage_index, task_index,
             "rank " + std::to_string(task_index) + " lost: " + message);
}

void Scheduler::TaskError(Job* job, size_t stage_index, int task_index, const std::string& message,
                          bool bad_input) {
  Stage& stage = job->stages[stage_index];
  Task& task = stage.tasks[static_cast<size_t>(task_index)];
  if (task.state != TaskState::kPending) return;
  ++task.errors;
  ++counters_.errors;
  task.message = message;
  if (bad_input || task.errors >= stage.spec.max_attempts) {
    task.state = TaskState::kFailed;
    ++stage.failed;
    ++counters_.failed;
    const std::string report =
        "task " + std::to_string(task_index) +
        (bad_input ? " rejected its input: "
                   : " failed after " + std::to_string(task.errors) + " attempt(s): ") +
        message;
    stage.failures.push_back(report);
    journal_->UpdateTask(job->id, stage.spec.name, task_index, task.state, task.errors, task.lost,
                         report);
    FinishJob(job, "failed", "stage '" + stage.spec.name + "': " + report);
    return;
  }
  task.not_before =
      clock_->Now() + stage.spec.retry_backoff_seconds * std::pow(2.0, task.errors - 1);
  journal_->UpdateTask(job->id, stage.spec.name, task_index, task.state, task.errors, task.lost,
                       message);
  Enqueue(job, stage_index, task_index);
  if (stage.gang())
    StopGang(job, stage_index, task_index, "rank " + std::to_string(task_index) + ": " + message);
}

void Scheduler::Commit(Job* job, size_t stage_index, int task_index, const Attempt& attempt,
                       const wire::TaskResult& result) {
  Stage& stage = job->stages[stage_index];
  Task& task = stage.tasks[static_cast<size_t>(task_index)];
  const std::string staging = StagingDir(*job, stage, task_index, attempt.id);
  const std::string final_dir = TaskDir(*job, stage, task_index);
  std::error_code ec;
  if (fs::exists(staging, ec)) {
    if (fs::exists(final_dir, ec)) {
      // A previous attempt committed its files before the journal recorded it (a coordinator crash
      // in between): the first commit wins.
      fs::remove_all(staging, ec);
      ++counters_.duplicates;
      if (const Status synced = SyncDir(fs::path(final_dir).parent_path().string()); !synced.ok()) {
        TaskError(job, stage_index, task_index, "commit not durable: " + synced.message(), false);
        return;
      }
    } else {
      fs::create_directories(fs::path(final_dir).parent_path(), ec);
      if (!stage.dir_synced) {
        // The stage's directory (made by the first worker to stage an attempt in it) gets its
        // entry in the job's directory synced before anything in it is committed.
        if (const Status synced = SyncDir(job->output_dir); !synced.ok()) {
          TaskError(job, stage_index, task_index, "commit not durable: " + synced.message(), false);
          return;
        }
        stage.dir_synced = true;
      }
      fs::rename(staging, final_dir, ec);
      if (ec) {
        TaskError(job, stage_index, task_index, "cannot commit " + staging + ": " + ec.message(),
                  false);
        return;
      }
      // The rename reaches the disk before the journal records the commit (the journal is
      // flushed after this returns): both directories' entries, as LevelDB syncs its manifest's.
      Status synced = SyncDir(fs::path(final_dir).parent_path().string());
      if (synced.ok()) synced = SyncDir(fs::path(staging).parent_path().string());
      if (!synced.ok()) {
        TaskError(job, stage_index, task_index, "commit not durable: " + synced.message(), false);
        return;
      }
    }
  } else if (result.outputs_size() > 0 && !fs::exists(final_dir, ec)) {
    TaskError(job, stage_index, task_index,
              "the attempt reported outputs but its directory " + staging + " is missing", false);
    return;
  }
  task.state = TaskState::kCommitted;
  task.message.clear();
  task.outputs.clear();
  for (const wire::OutputFile& out : result.outputs()) {
    task.outputs.push_back({out.path(), out.sha256(), out.bytes()});
    counters_.bytes_committed += out.bytes();
  }
  ++stage.committed;
  ++counters_.committed;
  stage.commit_times.push_back(clock_->Now());
  if (stage.commit_times.size() > 512) stage.commit_times.pop_front();
  journal_->UpdateTask(job->id, stage.spec.name, task_index, task.state, task.errors, task.lost,
                       "");
  journal_->AddOutputs(job->id, stage.spec.name, task_index, task.outputs);
  StageProgress(job, stage_index);
}

void Scheduler::StageProgress(Job* job, size_t stage_index) {
  Stage& stage = job->stages[stage_index];
  // The reduce task becomes ready once every shard has committed.
  if (stage.spec.reduce && stage.committed == stage.spec.shards) {
    const int reduce = stage.spec.shards;
    if (stage.waiting.count(reduce) &&
        stage.tasks[static_cast<size_t>(reduce)].not_before <= clock_->Now()) {
      stage.waiting.erase(reduce);
      stage.ready.push_back(reduce);
    }
  }
  if (stage.committed == static_cast<int>(stage.tasks.size())) {
    std::error_code ec;
    fs::remove(job->output_dir + "/" + stage.spec.name + "/.staging", ec);  // only when empty
  }
  if (job->state != "running") return;
  for (const Stage& s : job->stages) {
    if (s.committed != static_cast<int>(s.tasks.size())) return;
  }
  FinishJob(job, "succeeded", "");
}

void Scheduler::FinishJob(Job* job, const std::string& state, const std::string& error) {
  if (job->state != "running" && job->state != "pending") return;
  job->state = state;
  job->error = error;
  job->finished = clock_->Now();
  journal_->UpdateJob(job->id, state, job->finished, error);
  // Attempts still running for this job are cancelled; their results will be discarded.
  for (auto& [id, attempt] : attempts_) {
    if (attempt.job != job->id || attempt.expired) continue;
    Outgoing out;
    out.identity = attempt.identity;
    out.cancel.emplace();
    out.cancel->set_attempt_id(id);
    out.cancel->set_reason("job " + std::to_string(job->id) + " " + state);
    outgoing_.push_back(std::move(out));
  }
  if (state == "succeeded") {
    MP_LOG(kInfo, "coordinator") << "job " << job->id << " '" << job->spec.name << "' succeeded in "
                                 << static_cast<int64_t>(job->finished - job->created) << " s";
  } else {
    MP_LOG(kWarn, "coordinator") << "job " << job->id << " '" << job->spec.name << "' " << state
                                 << ": " << error;
  }
}

void Scheduler::OnResult(const std::string& identity, const wire::TaskResult& result) {
  OnSeen(identity);
  const auto it = attempts_.find(result.attempt_id());
  if (it == attempts_.end()) {
    // Unknown attempt: from before a coordinator restart, or the worker was already declared lost.
    // Nothing to commit through it; a re-queued attempt will produce the output.
    ++counters_.duplicates;
    return;
  }
  const Attempt attempt = it->second;
  ReleaseAttempt(result.attempt_id());
  if (const auto w = workers_.find(identity); w != workers_.end()) ++w->second.done;
  Job* job = FindJob(attempt.job);
  if (!job) return;
  Stage& stage = job->stages[attempt.stage];
  Task& task = stage.tasks[static_cast<size_t>(attempt.task)];
  std::error_code ec;
  if (job->state != "running" || task.state != TaskState::kPending) {
    // The job ended or another attempt committed first: this result is a duplicate.
    fs::remove_all(StagingDir(*job, stage, attempt.task, attempt.id), ec);
    ++counters_.duplicates;
    return;
  }
  switch (result.outcome()) {
    case wire::TaskResult::OK:
      Commit(job, attempt.stage, attempt.task, attempt, result);
      break;
    case wire::TaskResult::HANDED_BACK:
      ++counters_.handed_back;
      fs::remove_all(StagingDir(*job, stage, attempt.task, attempt.id), ec);
      Enqueue(job, attempt.stage, attempt.task);
      break;
    case wire::TaskResult::BAD_INPUT:
    case wire::TaskResult::ERROR:
    default:
      fs::remove_all(StagingDir(*job, stage, attempt.task, attempt.id), ec);
      if (attempt.expired) return;         // its expiry was already counted as the error
      if (task.live_attempts > 0) return;  // another attempt is still running it
      TaskError(job, attempt.stage, attempt.task, result.message(),
                result.outcome() == wire::TaskResult::BAD_INPUT);
      break;
  }
}

void Scheduler::Tick() {
  const double now = clock_->Now();
  // Dead workers: silent for liveness heartbeats.
  std::vector<std::string> dead;
  for (const auto& [identity, worker] : workers_) {
    if (now - worker.last_seen > options_.liveness * options_.heartbeat_seconds)
      dead.push_back(identity);
  }
  for (const std::string& identity : dead) {
    DropWorker(identity, "missed " + std::to_string(options_.liveness) + " heartbeats");
    lost_workers_.push_back(identity);
  }
  // Expired leases on live (but slow) workers: the task moves on; the slow attempt may still commit
  // if it finishes first.
  for (auto& [id, attempt] : attempts_) {
    if (attempt.expired || attempt.deadline > now) continue;
    attempt.expired = true;
    ++counters_.lease_expired;
    Job* job = FindJob(attempt.job);
    if (!job) continue;
    Stage& stage = job->stages[attempt.stage];
    Task& task = stage.tasks[static_cast<size_t>(attempt.task)];
    --task.live_attempts;
    --stage.running;
    const std::string worker =
        workers_.count(attempt.identity) ? workers_[attempt.identity].ready.worker_id() : "?";
    Outgoing out;
    out.identity = attempt.identity;
    out.cancel.emplace();
    out.cancel->set_attempt_id(id);
    out.cancel->set_reason("lease expired");
    outgoing_.push_back(std::move(out));
    if (job->state == "running" && task.state == TaskState::kPending) {
      TaskError(job, attempt.stage, attempt.task,
                "lease expired after " +
                    std::to_string(static_cast<int>(stage.spec.timeout_seconds)) + " s on worker " +
                    worker,
                false);
    }
  }
  // Backoff over.
  for (auto& [id, job] : jobs_) {
    if (job.state != "running") continue;
    for (size_t s = 0; s < job.stages.size(); ++s) {
      Stage& stage = job.stages[s];
      if (stage.waiting.empty()) continue;
      const std::set<int> waiting = stage.waiting;
      for (int t : waiting) Enqueue(&job, s, t);
    }
  }
  FireSchedules();
  Dispatch();
}

void Scheduler::FireSchedules() {
  const double now = clock_->Now();
  for (StoredSchedule& schedule : schedules_) {
    if (schedule.next_fire <= 0 || schedule.next_fire > now) continue;
    auto spec = ParsePipeline(schedule.pipeline, {}, "schedule " + schedule.name, kinds_);
    auto cron = ParseCron(schedule.cron);
    schedule.next_fire = cron.ok() ? NextFireTime(*cron, static_cast<int64_t>(now)) : -1;
    if (const Status s = journal_->SetScheduleNextFire(schedule.id, schedule.next_fire); !s.ok()) {
      MP_LOG(kError, "coordinator") << s.message();
    }
    if (!spec.ok()) {
      MP_LOG(kError, "coordinator") << "scheduled pipeline '" << schedule.name
                                    << "' no longer valid: " << spec.status().message();
      continue;
    }
    auto job = CreateJob(*spec);
    MP_LOG(kInfo, "coordinator") << "schedule '" << schedule.name << "' fired: job "
                                 << (job.ok() ? std::to_string(*job) : job.status().message());
  }
}

std::vector<Outgoing> Scheduler::TakeOutgoing() { return std::exchange(outgoing_, {}); }
std::vector<std::string> Scheduler::TakeLostWorkers() { return std::exchange(lost_workers_, {}); }

int64_t Scheduler::pending_tasks() const {
  int64_t pending = 0;
  for (const auto& [id, job] : jobs_) {
    if (job.state != "running") continue;
    for (const Stage& stage : job.stages)
      pending += static_cast<int64_t>(stage.ready.size() + stage.waiting.size());
  }
  return pending;
}

bool Scheduler::AllJobsFinished() const {
  for (const auto& [id, job] : jobs_) {
    if (job.state == "running" || job.state == "pending") return false;
  }
  return true;
}

std::string Scheduler::JobState(int64_t job_id) const {
  const auto it = jobs_.find(job_id);
  return it == jobs_.end() ? "" : it->second.state;
}

std::vector<wire::JobStatus> Scheduler::JobStatuses(int64_t job_id) const {
  std::vector<wire::JobStatus> out;
  const double now = clock_->Now();
  for (const auto& [id, job] : jobs_) {
    if (job_id != 0 && id != job_id) continue;
    wire::JobStatus status;
    status.set_id(id);
    status.set_name(job.spec.name);
    status.set_state(job.state);
    status.set_created_unix(job.created);
    status.set_finished_unix(job.finished);
    status.set_output_dir(job.output_dir);
    status.set_error(job.error);
    for (const Stage& stage : job.stages) {
      wire::StageStatus* s = status.add_stages();
      s->set_name(stage.spec.name);
      s->set_kind(stage.spec.kind);
      const int total = static_cast<int>(stage.tasks.size());
      int quarantined = 0;
      for (const Task& t : stage.tasks) quarantined += t.state == TaskState::kQuarantined;
      s->set_total(total);
      s->set_committed(stage.committed);
      s->set_running(stage.running);
      s->set_failed(stage.failed - quarantined);
      s->set_quarantined(quarantined);
      s->set_pending(total - stage.committed - stage.failed - stage.running);
      const std::string state = stage.failed > 0           ? "failed"
                                : stage.committed == total ? "succeeded"
                                : !InputsDone(job, stage)  ? "waiting"
                                : stage.started            ? "running"
                                                           : "ready";
      s->set_state(state);
      // Throughput over the recent commits, and the time left at that pace.
      double rate = 0;
      if (stage.commit_times.size() >= 2) {
        const double span =
            std::max(1e-3, std::max(now, stage.commit_times.back()) - stage.commit_times.front());
        rate = static_cast<double>(stage.commit_times.size() - 1) / span;
      }
      s->set_tasks_per_second(rate);
      s->set_eta_seconds(rate > 0 ? (total - stage.committed) / rate
                                  : (stage.committed == total ? 0 : -1));
      for (const std::string& f : stage.failures) s->add_failures(f);
      if (stage.spec.reduce) s->set_result_dir(TaskDir(job, stage, stage.spec.shards));
    }
    out.push_back(std::move(status));
  }
  return out;
}

std::vector<wire::WorkerStatus> Scheduler::WorkerStatuses() const {
  std::vector<wire::WorkerStatus> out;
  const double now = clock_->Now();
  for (const auto& [identity, worker] : workers_) {
    wire::WorkerStatus w;
    w.set_id(worker.ready.worker_id());
    w.set_state(worker.draining ? "draining" : (worker.attempts.empty() ? "idle" : "busy"));
    w.set_running(static_cast<int>(worker.attempts.size()));
    w.set_credit(worker.ready.credit());
    for (const std::string& kind : worker.kinds) w.add_kinds(kind);
    w.set_last_seen_seconds(now - worker.last_seen);
    w.set_tasks_done(worker.done);
    out.push_back(std::move(w));
  }
  return out;
}

}  // namespace motionpipe::coordinator
