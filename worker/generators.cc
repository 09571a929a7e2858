#include "generators.h"

#include <filesystem>

#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"

namespace motionpipe::worker {

namespace fs = std::filesystem;

Result<std::string> ResolveCheckpoint(const std::string& path) {
  if (!fs::exists(path)) return NotFound(path + ": no such checkpoint directory");
  for (const std::string& candidate :
       {path, layout::CheckpointDir(path), layout::CheckpointDir(layout::TaskDir(path))}) {
    if (fs::exists(layout::ModelConfigFile(candidate))) return candidate;
  }
  return NotFound(path +
                  ": not a checkpoint (no model.json in it, in model/ or in task-00000/model/)");
}

Result<std::string> CheckpointModelName(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const std::string dir, ResolveCheckpoint(path));
  MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(layout::ModelConfigFile(dir)));
  nlohmann::json meta;
  try {
    meta = nlohmann::json::parse(text);
  } catch (const std::exception& e) {
    return DataLoss(layout::ModelConfigFile(dir) + ": " + e.what());
  }
  // A name that is not a string is no name (json's value() would throw on it).
  const bool named = meta.is_object() && meta.contains("name") && meta["name"].is_string();
  const std::string name = named ? meta["name"].get<std::string>() : std::string();
  if (name.empty()) return DataLoss(layout::ModelConfigFile(dir) + ": no model name");
  return name;
}

Result<GeneratorPtr> LoadGenerator(const PluginHost& plugins, const std::string& path,
                                   const nlohmann::json& options) {
  MP_ASSIGN_OR_RETURN(const std::string dir, ResolveCheckpoint(path));
  MP_ASSIGN_OR_RETURN(const std::string name, CheckpointModelName(dir));
  const mp_object_factory* factory = plugins.FindFactory("generator", name);
  if (!factory)
    return NotFound(dir + ": model '" + name +
                    "' needs its plugin, which is not loaded (see `motionpipe plugins list`)");
  nlohmann::json config = options.is_object() ? options : nlohmann::json::object();
  config["checkpoint"] = dir;
  char error[2048] = {0};
  void* object = factory->create(config.dump().c_str(), error, sizeof error);
  if (!object)
    return InvalidArgument(dir + ": " +
                           std::string(error[0] ? error : "the plugin could not load it"));
  // The plugin made the object, so the plugin's factory destroys it.
  return GeneratorPtr(static_cast<plugin::Generator*>(object),
                      [factory](plugin::Generator* g) { factory->destroy(g); });
}

}  // namespace motionpipe::worker
