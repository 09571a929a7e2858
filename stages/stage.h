// What every stage kind's file includes: the engine's stage interface (worker/executor.h) named in
// this namespace, and the registration macros. A kind is one file, stages/<kind>.cc: a
// StageExecutor (Plan in the coordinator, Run in the worker) and one MP_STAGE_KIND line.
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <type_traits>

#include "executor.h"
#include "generators.h"
#include "plugin_host.h"

namespace motionpipe::stages {

using nlohmann::json;
using worker::CheckInputListParams;
using worker::CheckInputParams;
using worker::GeneratorPtr;
using worker::IntParam;
using worker::LoadGenerator;
using worker::LongLease;
using worker::PluginHost;
using worker::ResolveCheckpoint;
using worker::StageExecutor;
using worker::StagePlan;
using worker::TaskContext;
using worker::TaskReport;

// The factory AddBuiltinKind takes: stages that use plugins (labelers, generators) are built with
// the worker's plugin host, the others without.
template <typename Stage>
std::unique_ptr<StageExecutor> MakeStage(const PluginHost* plugins) {
  if constexpr (std::is_constructible_v<Stage, const PluginHost*>) {
    return std::make_unique<Stage>(plugins);
  } else {
    (void)plugins;
    return std::make_unique<Stage>();
  }
}

}  // namespace motionpipe::stages

#define MP_STAGE_CONCAT_(a, b) a##b
#define MP_STAGE_CONCAT(a, b) MP_STAGE_CONCAT_(a, b)
// MP_STAGE_KIND("edit", EditStage): registers the kind at static initialisation.
#define MP_STAGE_KIND(kind, Stage)                                            \
  [[maybe_unused]] static const bool MP_STAGE_CONCAT(stage_kind_, __LINE__) = \
      ::motionpipe::worker::AddBuiltinKind(kind, &::motionpipe::stages::MakeStage<Stage>)
// MP_STAGE_PLANNER("train", PlanTrainStage): a kind planned here and run by a plugin.
#define MP_STAGE_PLANNER(kind, planner)                                          \
  [[maybe_unused]] static const bool MP_STAGE_CONCAT(stage_planner_, __LINE__) = \
      ::motionpipe::worker::AddBuiltinPlanner(kind, planner)
