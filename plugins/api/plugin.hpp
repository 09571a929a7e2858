// C++ conveniences for plugin authors on top of the C ABI (motionpipe_plugin.h): parse the task
// JSON, run a stage function with exceptions turned into task errors, and define the entry point.
#pragma once

#include <cstdio>
#include <exception>
#include <nlohmann/json.hpp>
#include <string>

#include "motionpipe_plugin.h"

namespace motionpipe::plugin {

struct Task {
  nlohmann::json spec;  // the whole TaskSpec
  const mp_task_io* io;
  const nlohmann::json& params() const { return spec["params"]; }
  std::string output_dir() const { return spec["output_dir"].get<std::string>(); }
  bool cancelled() const { return io->cancel && *io->cancel != 0; }
  void Metric(const std::string& name, double value) const {
    if (io->report_metric) io->report_metric(io->host, name.c_str(), value);
  }
  void Log(int level, const std::string& message) const {
    if (io->log) io->log(io->host, level, message.c_str());
  }
  // An object factory of any loaded plugin (ABI 2), or nullptr.
  const mp_object_factory* Factory(const std::string& kind, const std::string& name) const {
    return io->find_factory ? io->find_factory(io->host, kind.c_str(), name.c_str()) : nullptr;
  }
};

// Thrown by a stage function for input that can never succeed (the task fails at once).
struct BadInput : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Runs `fn(const Task&)` and maps the outcome: exceptions (including LibTorch's) become task errors
// with their message; BadInput becomes MP_TASK_BAD_INPUT.
template <typename Fn>
int RunStage(const mp_task_io* io, char* error, size_t error_size, Fn fn) {
  try {
    Task task{nlohmann::json::parse(io->task_json), io};
    fn(task);
    return MP_TASK_OK;
  } catch (const BadInput& e) {
    std::snprintf(error, error_size, "%s", e.what());
    return MP_TASK_BAD_INPUT;
  } catch (const std::exception& e) {
    std::snprintf(error, error_size, "%s", e.what());
    return MP_TASK_ERROR;
  } catch (...) {
    std::snprintf(error, error_size, "unknown exception");
    return MP_TASK_ERROR;
  }
}

// An object factory's create(): builds the object from its JSON configuration with `make`;
// exceptions become the factory's error message, prefixed with the plugin's name.
template <typename Make>
void* CreateFromJson(const char* plugin_name, const char* config_json, char* error,
                     size_t error_size, Make make) {
  try {
    return make(nlohmann::json::parse(config_json ? config_json : "{}"));
  } catch (const std::exception& e) {
    std::snprintf(error, error_size, "%s: %s", plugin_name, e.what());
    return nullptr;
  }
}

}  // namespace motionpipe::plugin
