// Trained generators and editors by checkpoint, for the CLI and the evaluation stages, without
// linking LibTorch here: the checkpoint's model.json names the plugin whose ("generator", name)
// factory loads it.
#pragma once

#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "generator.hpp"
#include "plugin_host.h"

namespace motionpipe::worker {

using GeneratorPtr = std::unique_ptr<plugin::Generator, std::function<void(plugin::Generator*)>>;

// The checkpoint directory (the one holding model.json) from what a user may point at: that
// directory, a train task's output (…/task-00000, which holds model/), or a train stage's output
// (…/sinc, whose rank-0 task holds it).
Result<std::string> ResolveCheckpoint(const std::string& path);

// The model a checkpoint holds: the name its model.json gives (the plugin whose factory loads it),
// read without loading the weights. DataLoss naming the file when it has none.
Result<std::string> CheckpointModelName(const std::string& path);

// Loads the generator of a checkpoint; `options` are merged into the factory's configuration
// (e.g. {"compositing": true}).
Result<GeneratorPtr> LoadGenerator(const PluginHost& plugins, const std::string& path,
                                   const nlohmann::json& options = nlohmann::json::object());

}  // namespace motionpipe::worker
