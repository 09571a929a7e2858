#include "evaluation.h"

#include <prometheus/gateway.h>
#include <prometheus/gauge.h>
#include <prometheus/registry.h>

#include <algorithm>
#include <cmath>
#include <ctime>

#include "metric_history.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/base/log.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/motion/plausibility.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::stages {

namespace {

// Pushes this evaluation's headline metrics and its regressions to a Prometheus Pushgateway
// ("http://host:port"), grouped by job name and stage: motionpipe_eval_metric{method, metric},
// motionpipe_eval_regression{method, metric} (1 when it regressed) and motionpipe_eval_regressions.
// A gateway that cannot be reached is logged and recorded, not fatal: the metrics are on disk.
json PushToGateway(const TaskContext& ctx, const std::string& url, const std::string& method,
                   const std::vector<Tracked>& tracked,
                   const std::vector<report::Regression>& regressions) {
  const size_t colon = url.rfind(':');
  if (url.empty() || colon == std::string::npos || colon + 1 >= url.size() ||
      url.find("//") == std::string::npos) {
    MP_LOG(kWarn, "eval") << "pushgateway '" << url << "': expected http://host:port; not pushed";
    return {{"url", url}, {"error", "expected http://host:port"}};
  }
  auto registry = std::make_shared<prometheus::Registry>();
  auto& value = prometheus::BuildGauge()
                    .Name("motionpipe_eval_metric")
                    .Help("Headline evaluation metrics of the last run")
                    .Register(*registry);
  auto& regressed = prometheus::BuildGauge()
                        .Name("motionpipe_eval_regression")
                        .Help("1 when the metric regressed against its best")
                        .Register(*registry);
  auto& count = prometheus::BuildGauge()
                    .Name("motionpipe_eval_regressions")
                    .Help("Regressions found by the last evaluation run")
                    .Register(*registry);
  for (const Tracked& t : tracked) {
    value.Add({{"method", method}, {"metric", t.name}}).Set(t.value);
    const bool bad = std::any_of(regressions.begin(), regressions.end(),
                                 [&](const report::Regression& r) { return r.metric == t.name; });
    regressed.Add({{"method", method}, {"metric", t.name}}).Set(bad ? 1 : 0);
  }
  count.Add({{"method", method}}).Set(static_cast<double>(regressions.size()));
  prometheus::Gateway gateway(url.substr(0, colon), url.substr(colon + 1), "motionpipe_eval",
                              {{"pipeline", ctx.spec.job_name()}, {"stage", ctx.spec.stage()}});
  gateway.RegisterCollectable(registry);
  const int status = gateway.Push();
  if (status < 200 || status >= 300) {
    MP_LOG(kWarn, "eval") << "pushgateway " << url << ": push failed (HTTP status " << status
                          << ")";
  } else {
    MP_LOG(kInfo, "eval") << "pushed " << tracked.size() << " metric(s) and " << regressions.size()
                          << " regression(s) to " << url;
  }
  return {{"url", url}, {"status", status}};
}

}  // namespace

json ScoresJson(const eval::RetrievalScores& s) {
  return {
      {"R@1", s.r1}, {"R@2", s.r2}, {"R@3", s.r3}, {"AvgR", s.avg_rank}, {"queries", s.queries}};
}

json MeanPlausibility(const std::vector<Motion>& motions) {
  double skate = 0, skate_gmd = 0, penetration = 0, floating = 0, jerk = 0;
  for (const Motion& m : motions) {
    const auto r = EvaluateMotionPlausibility(Skeleton::Smpl22(), m);
    skate += r.foot_skate_ratio, skate_gmd += r.skating_ratio_gmd,
        penetration += r.penetration_mean, floating += r.float_ratio, jerk += r.jerk_mean;
  }
  const double n = static_cast<double>(std::max<size_t>(1, motions.size()));
  return json{{"foot_skate_ratio", skate / n},
              {"skating_ratio_gmd", skate_gmd / n},
              {"penetration_mean_m", penetration / n},
              {"float_ratio", floating / n},
              {"jerk_mean", jerk / n}};
}

Status WritePreview(const TaskContext& ctx,
                    const std::vector<std::pair<std::string, const Motion*>>& roles,
                    const std::string& text, const std::string& example) {
  std::vector<Clip> clips;
  for (const auto& [role, motion] : roles) {
    Clip clip;
    clip.id = role;
    clip.source = example;
    clip.motion = *motion;
    clip.texts = {text};
    clips.push_back(std::move(clip));
  }
  return WriteClips(ctx.output_dir() + "/preview.npz", clips);
}

double Cosine(const std::vector<float>& a, const std::vector<float>& b) {
  double dot = 0, na = 0, nb = 0;
  for (size_t k = 0; k < a.size(); ++k) dot += a[k] * b[k], na += a[k] * a[k], nb += b[k] * b[k];
  return dot / std::max(1e-12, std::sqrt(na * nb));
}

eval::Embeddings ToEmbeddings(const std::vector<std::vector<float>>& rows) {
  eval::Embeddings e{static_cast<int64_t>(rows.size()),
                     rows.empty() ? 0 : static_cast<int64_t>(rows[0].size()),
                     {}};
  for (const auto& row : rows) e.values.insert(e.values.end(), row.begin(), row.end());
  return e;
}

void ReadSummary(const std::string& path, std::string* method, std::string* checkpoint) {
  auto text = ReadFile(path);
  if (!text.ok()) return;
  const json summary = json::parse(*text, nullptr, false);
  if (summary.is_discarded()) return;
  if (method->empty()) *method = summary.value("model", std::string());
  if (checkpoint->empty()) *checkpoint = summary.value("checkpoint", std::string());
}

std::optional<TaskReport> RecordHistory(const TaskContext& ctx, json* metrics,
                                        const std::string& method, const std::string& checkpoint,
                                        const std::vector<std::string>& ids,
                                        const std::vector<Tracked>& tracked) {
  const json& p = ctx.params;
  const std::string path = p.value("history", std::string());
  if (path.empty()) return std::nullopt;
  std::string data;
  for (const auto& id : ids) data += id + "\n";
  auto config = ReadFile(layout::ModelConfigFile(checkpoint));
  std::vector<report::MetricRecord> records;
  for (const Tracked& t : tracked) {
    report::MetricRecord r;
    r.method = method;
    r.metric = t.name;
    r.value = t.value;
    r.higher_is_better = t.higher_is_better;
    r.checkpoint = checkpoint;
    r.config_hash = config.ok() ? report::HashText(*config) : "";
    r.data_hash = report::HashText(data);
    r.job = std::to_string(ctx.spec.job_id());
    r.time_unix = static_cast<int64_t>(std::time(nullptr));
    records.push_back(r);
  }
  auto regressions = report::AppendAndCompare(path, records, p.value("regression_margin", 0.0));
  if (!regressions.ok()) return TaskReport::Error(regressions.status().message());
  (*metrics)["history"] = path;
  (*metrics)["regressions"] = json::array();
  for (const auto& r : *regressions) {
    (*metrics)["regressions"].push_back({{"metric", r.metric},
                                         {"value", r.value},
                                         {"best", r.best},
                                         {"best_checkpoint", r.best_checkpoint}});
    MP_LOG(kWarn, "eval") << "regression: " << r.Describe();
  }
  if (p.contains("pushgateway"))
    (*metrics)["pushgateway"] =
        PushToGateway(ctx, p.value("pushgateway", std::string()), method, tracked, *regressions);
  if (!regressions->empty() && p.value("fail_on_regression", false)) {
    (void)WriteFileAtomic(layout::MetricsFile(ctx.output_dir()),
                          metrics->dump(1) + "\n");  // for the record; the task fails
    return TaskReport::BadInput("regression: " + regressions->front().Describe() +
                                (regressions->size() > 1
                                     ? " (and " + std::to_string(regressions->size() - 1) + " more)"
                                     : ""));
  }
  return std::nullopt;
}

void AddTiming(json* metrics, std::chrono::steady_clock::time_point started,
               size_t motions_scored) {
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  (*metrics)["seconds"] = seconds;
  (*metrics)["motions_scored"] = motions_scored;
  (*metrics)["motions_scored_per_second"] =
      seconds > 0 ? static_cast<double>(motions_scored) / seconds : 0.0;
}

TaskReport WriteMetrics(const TaskContext& ctx, const json& metrics) {
  if (Status st = WriteFileAtomic(layout::MetricsFile(ctx.output_dir()), metrics.dump(1) + "\n");
      !st.ok())
    return TaskReport::Error(st.message());
  TaskReport out = TaskReport::Ok();
  out.metrics["regressions"] =
      metrics.contains("regressions") ? static_cast<double>(metrics["regressions"].size()) : 0.0;
  return out;
}

}  // namespace motionpipe::stages
