// The sample plugin: proves the plugin path end to end with a trivial stage kind.
// `sample.checksum` lists the files of its input stages and writes their total size and a checksum
// of their names to checksum.json; `sample.echo` writes its params back.
#include <filesystem>
#include <fstream>

#include "../api/plugin.hpp"

namespace {

void Checksum(const motionpipe::plugin::Task& task) {
  uint64_t files = 0, bytes = 0, hash = 1469598103934665603ull;  // FNV-1a over relative paths
  for (const auto& input : task.spec["inputs"]) {
    for (const auto& dir : input["dirs"]) {
      const std::string root = dir.get<std::string>();
      if (!std::filesystem::exists(root))
        throw motionpipe::plugin::BadInput("input directory " + root + " is missing");
      for (const auto& entry : std::filesystem::recursive_directory_iterator(root)) {
        if (!entry.is_regular_file()) continue;
        ++files;
        bytes += entry.file_size();
        for (char c : std::filesystem::relative(entry.path(), root).string())
          hash = (hash ^ static_cast<unsigned char>(c)) * 1099511628211ull;
      }
    }
  }
  std::filesystem::create_directories(task.output_dir());
  std::ofstream out(task.output_dir() + "/checksum.json");
  out << nlohmann::json{{"files", files}, {"bytes", bytes}, {"names_fnv1a", hash}}.dump() << "\n";
  task.Metric("files", static_cast<double>(files));
}

void Echo(const motionpipe::plugin::Task& task) {
  std::filesystem::create_directories(task.output_dir());
  std::ofstream(task.output_dir() + "/params.json") << task.params().dump() << "\n";
}

const mp_stage_kind kKinds[] = {
    {"sample.checksum", "count and checksum the files of the input stages",
     [](const mp_task_io* io, char* error, size_t size) {
       return motionpipe::plugin::RunStage(io, error, size, Checksum);
     }},
    {"sample.echo", "write the stage params back",
     [](const mp_task_io* io, char* error, size_t size) {
       return motionpipe::plugin::RunStage(io, error, size, Echo);
     }},
};

const mp_plugin kPlugin = {
    MOTIONPIPE_PLUGIN_ABI_VERSION, sizeof(mp_plugin), "sample", "1.0.0", 2, kKinds, 0, nullptr};

}  // namespace

extern "C" __attribute__((visibility("default"))) const mp_plugin* motionpipe_plugin_v1(void) {
  return &kPlugin;
}
