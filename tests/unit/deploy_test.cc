// The deployment files stay well-formed: every YAML parses (Kubernetes, Prometheus), the Grafana
// dashboard is JSON whose queries name metrics the engine exports, the shell scripts pass `bash
// -n`.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>

#include "motionpipe/base/file.h"

namespace {

const std::string kDeploy = std::string(MOTIONPIPE_SOURCE_DIR) + "/deploy";

TEST(Deploy, KubernetesAndPrometheusYamlParse) {
  int documents = 0;
  for (const char* file : {"k8s/pvc.yaml", "k8s/coordinator.yaml", "k8s/workers.yaml",
                           "k8s/submit-job.yaml", "prometheus/prometheus.yml"}) {
    for (const YAML::Node& doc : YAML::LoadAllFromFile(kDeploy + "/" + file)) {
      ASSERT_TRUE(doc.IsMap()) << file;
      if (std::string(file).rfind("k8s/", 0) == 0) {
        EXPECT_TRUE(doc["kind"] && doc["apiVersion"] && doc["metadata"]["name"]) << file;
      }
      ++documents;
    }
  }
  EXPECT_EQ(documents, 6);
  const YAML::Node workers = YAML::LoadFile(kDeploy + "/k8s/workers.yaml");
  const YAML::Node spec = workers["spec"]["template"]["spec"];
  // Preemption must leave time for the drain.
  EXPECT_GT(spec["terminationGracePeriodSeconds"].as<int>(), 120);
}

TEST(Deploy, GrafanaDashboardQueriesExportedMetrics) {
  const auto dashboard =
      nlohmann::json::parse(*motionpipe::ReadFile(kDeploy + "/grafana/motionpipe-dashboard.json"));
  const std::string sources =
      *motionpipe::ReadFile(std::string(MOTIONPIPE_SOURCE_DIR) + "/coordinator/server.cc") +
      *motionpipe::ReadFile(std::string(MOTIONPIPE_SOURCE_DIR) + "/worker/worker.cc");
  const std::regex metric("motionpipe_[a-z_]+");
  int queries = 0;
  for (const auto& panel : dashboard["panels"]) {
    for (const auto& target : panel["targets"]) {
      const std::string expr = target["expr"];
      for (std::sregex_iterator it(expr.begin(), expr.end(), metric), end; it != end; ++it) {
        std::string name = it->str();
        for (const char* suffix : {"_bucket", "_count", "_sum"}) {
          if (name.size() > std::strlen(suffix) &&
              name.compare(name.size() - std::strlen(suffix), std::strlen(suffix), suffix) == 0) {
            name.resize(name.size() - std::strlen(suffix));
          }
        }
        EXPECT_NE(sources.find("\"" + name + "\""), std::string::npos)
            << name << " in panel " << panel["title"];
        ++queries;
      }
    }
  }
  EXPECT_GT(queries, 10);
}

TEST(Deploy, ShellScriptsParse) {
  for (const char* script : {"/deploy/slurm/motionpipe.sbatch", "/scripts/setup", "/scripts/test",
                             "/scripts/demo", "/scripts/fuzz"}) {
    const std::string command = "bash -n " + std::string(MOTIONPIPE_SOURCE_DIR) + script;
    EXPECT_EQ(std::system(command.c_str()), 0) << script;
  }
}

}  // namespace
