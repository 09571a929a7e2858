// Labelers by name for workers and the CLI: the built-in ones (core/labels) first, then factories
// of kind "labeler" from loaded plugins (e.g. `learned` from plugins/labelers).
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "motionpipe/labels/labeler.h"
#include "plugin_host.h"

namespace motionpipe::worker {

Result<std::unique_ptr<labels::Labeler>> MakeLabeler(const std::string& name,
                                                     const nlohmann::json& config,
                                                     const PluginHost* plugins);

}  // namespace motionpipe::worker
