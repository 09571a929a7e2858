// Loads plugin libraries through the one C ABI entry point (plugins/api/motionpipe_plugin.h):
// dlopen with RTLD_LOCAL, ABI version checked before anything else is touched, never unloaded. A
// bad plugin (cannot load, missing symbol, wrong ABI, throws in its entry point) is reported and
// skipped; the host keeps going.
#pragma once

#include <string>
#include <vector>

#include "executor.h"
#include "motionpipe/base/status.h"
#include "motionpipe_plugin.h"

namespace motionpipe::worker {

struct LoadedPlugin {
  std::string path;
  std::string canonical_path;
  std::string name;
  std::string version;
  std::vector<std::string> stage_kinds;
  std::vector<std::string> objects;  // "kind/name" of its factories
  const mp_plugin* plugin = nullptr;
};

struct PluginProblem {
  std::string path;
  std::string message;
};

class PluginHost {
 public:
  // Loads every *.so in `dir` (a missing directory is not an error). Problems are collected.
  void LoadDirectory(const std::string& dir);
  // Loads one library; the Status says why it was refused.
  Status LoadFile(const std::string& path);

  const std::vector<LoadedPlugin>& plugins() const { return plugins_; }
  const std::vector<PluginProblem>& problems() const { return problems_; }

  // Adds an executor for every stage kind of every loaded plugin.
  void RegisterExecutors(ExecutorRegistry* registry) const;
  // The factory for objects of `kind` named `name` ("model"/"temos_sinc"), or nullptr.
  const mp_object_factory* FindFactory(const std::string& kind, const std::string& name) const;

 private:
  std::vector<LoadedPlugin> plugins_;
  std::vector<PluginProblem> problems_;
};

// Default plugin directories: $MOTIONPIPE_PLUGIN_PATH (':'-separated), then ../plugins next to the
// running binary (the build tree's layout) and <prefix>/lib/motionpipe/plugins.
std::vector<std::string> DefaultPluginDirs();

}  // namespace motionpipe::worker
