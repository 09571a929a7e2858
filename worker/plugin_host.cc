#include "plugin_host.h"

#include <dlfcn.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <thread>

#include "motionpipe/base/cpu_kernels.h"
#include "motionpipe/base/log.h"

namespace motionpipe::worker {

namespace {

// Adapts a plugin's C stage function to the executor interface.
class PluginStage : public StageExecutor {
 public:
  PluginStage(const mp_stage_kind* kind, std::string plugin, const PluginHost* host)
      : kind_(kind), plugin_(std::move(plugin)), plugins_(host) {}
  std::string Description() const override {
    return std::string(kind_->description ? kind_->description : "") + " (plugin " + plugin_ + ")";
  }
  TaskReport Run(TaskContext& ctx) override {
    const std::string json = TaskSpecToJson(ctx.spec);
    volatile int cancel_flag = 0;
    TaskReport report;
    struct Host {
      TaskReport* report;
      std::string plugin;
      const PluginHost* plugins;
      const TaskContext* ctx;
    } host{&report, plugin_, plugins_, &ctx};
    mp_task_io io{json.c_str(),
                  &cancel_flag,
                  &host,
                  [](void* h, const char* name, double value) {
                    Host* self = static_cast<Host*>(h);
                    self->report->metrics[name] = value;
                    if (self->ctx->on_metric) self->ctx->on_metric(name, value);
                  },
                  [](void* h, int level, const char* message) {
                    const LogLevel l = level <= 0   ? LogLevel::kDebug
                                       : level == 1 ? LogLevel::kInfo
                                       : level == 2 ? LogLevel::kWarn
                                                    : LogLevel::kError;
                    LogLine(l, "plugin " + static_cast<Host*>(h)->plugin, message);
                  },
                  [](void* h, const char* kind, const char* name) -> const mp_object_factory* {
                    const PluginHost* plugins = static_cast<Host*>(h)->plugins;
                    return plugins ? plugins->FindFactory(kind ? kind : "", name ? name : "")
                                   : nullptr;
                  }};
    // The plugin reads a plain int; mirror the atomic cancel flag into it from a watcher.
    std::atomic<bool> done{false};
    std::thread watcher([&] {
      while (!done) {
        if (ctx.cancelled()) cancel_flag = 1;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
    });
    char error[2048] = {0};
    int rc = MP_TASK_ERROR;
    try {
      rc = kind_->run(&io, error, sizeof(error));
    } catch (const std::exception& e) {
      std::snprintf(error, sizeof(error), "plugin threw: %s", e.what());
      rc = MP_TASK_ERROR;
    } catch (...) {
      std::snprintf(error, sizeof(error), "plugin threw an unknown exception");
      rc = MP_TASK_ERROR;
    }
    done = true;
    watcher.join();
    report.outcome = rc == MP_TASK_OK          ? Outcome::kOk
                     : rc == MP_TASK_BAD_INPUT ? Outcome::kBadInput
                                               : Outcome::kError;
    report.message = error;
    return report;
  }

 private:
  const mp_stage_kind* kind_;
  std::string plugin_;
  const PluginHost* plugins_;
};

}  // namespace

Status PluginHost::LoadFile(const std::string& path) {
  std::error_code ec;
  const std::string canonical = std::filesystem::weakly_canonical(path, ec).string();
  for (const LoadedPlugin& loaded : plugins_) {
    if (loaded.canonical_path == canonical)
      return Status::Ok();  // the same file found twice: already loaded
  }
  const auto refuse = [&](const std::string& why) {
    problems_.push_back({path, why});
    MP_LOG(kWarn, "plugins") << path << ": " << why;
    return FailedPrecondition(path + ": " + why);
  };
  // The model plugins bring LibTorch and its OpenBLAS, which picks its kernels when loaded.
  PreferNativeBlasKernels();
  // RTLD_LOCAL: the plugin's symbols stay its own. Never dlclose: LibTorch code must stay mapped.
  void* handle = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) return refuse(std::string("cannot load: ") + ::dlerror());
  auto entry = reinterpret_cast<mp_plugin_entry_fn>(::dlsym(handle, MOTIONPIPE_PLUGIN_ENTRY));
  if (!entry) return refuse("no '" MOTIONPIPE_PLUGIN_ENTRY "' symbol: not a motionpipe plugin");
  const mp_plugin* plugin = nullptr;
  try {
    plugin = entry();
  } catch (const std::exception& e) {
    return refuse(std::string("its entry point threw: ") + e.what());
  } catch (...) {
    return refuse("its entry point threw an unknown exception");
  }
  if (!plugin) return refuse("its entry point returned nothing");
  if (plugin->abi_version != MOTIONPIPE_PLUGIN_ABI_VERSION) {
    return refuse("plugin ABI version " + std::to_string(plugin->abi_version) +
                  ", this host speaks version " + std::to_string(MOTIONPIPE_PLUGIN_ABI_VERSION) +
                  ": rebuild the plugin against this motionpipe");
  }
  if (plugin->struct_size < sizeof(mp_plugin))
    return refuse("plugin struct too small (built against an older header)");
  LoadedPlugin loaded;
  loaded.path = path;
  loaded.canonical_path = canonical;
  loaded.name = plugin->name ? plugin->name : "?";
  loaded.version = plugin->version ? plugin->version : "?";
  loaded.plugin = plugin;
  for (uint32_t k = 0; k < plugin->num_stage_kinds; ++k) {
    const mp_stage_kind& kind = plugin->stage_kinds[k];
    if (!kind.kind || !kind.run)
      return refuse("stage kind " + std::to_string(k) + " has no name or run function");
    loaded.stage_kinds.push_back(kind.kind);
  }
  for (uint32_t k = 0; k < plugin->num_factories; ++k) {
    const mp_object_factory& f = plugin->factories[k];
    if (!f.kind || !f.name || !f.create || !f.destroy)
      return refuse("factory " + std::to_string(k) + " is incomplete");
    loaded.objects.push_back(std::string(f.kind) + "/" + f.name);
  }
  for (const LoadedPlugin& other : plugins_) {
    if (other.name == loaded.name)
      return refuse("a plugin named '" + loaded.name + "' is already loaded from " + other.path);
  }
  plugins_.push_back(std::move(loaded));
  return Status::Ok();
}

void PluginHost::LoadDirectory(const std::string& dir) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return;
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    if (entry.path().extension() == ".so") files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  for (const std::string& file : files) (void)LoadFile(file);
}

void PluginHost::RegisterExecutors(ExecutorRegistry* registry) const {
  for (const LoadedPlugin& loaded : plugins_) {
    for (uint32_t k = 0; k < loaded.plugin->num_stage_kinds; ++k) {
      registry->Register(
          loaded.plugin->stage_kinds[k].kind,
          std::make_unique<PluginStage>(&loaded.plugin->stage_kinds[k], loaded.name, this));
    }
  }
}

const mp_object_factory* PluginHost::FindFactory(const std::string& kind,
                                                 const std::string& name) const {
  for (const LoadedPlugin& loaded : plugins_) {
    for (uint32_t k = 0; k < loaded.plugin->num_factories; ++k) {
      const mp_object_factory& f = loaded.plugin->factories[k];
      if (kind == f.kind && name == f.name) return &f;
    }
  }
  return nullptr;
}

std::vector<std::string> DefaultPluginDirs() {
  std::vector<std::string> dirs;
  if (const char* env = std::getenv("MOTIONPIPE_PLUGIN_PATH")) {
    std::string value = env;
    size_t start = 0;
    while (start <= value.size()) {
      const size_t colon = value.find(':', start);
      const std::string part =
          value.substr(start, colon == std::string::npos ? std::string::npos : colon - start);
      if (!part.empty()) dirs.push_back(part);
      if (colon == std::string::npos) break;
      start = colon + 1;
    }
  }
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    dirs.push_back((exe.parent_path().parent_path() / "plugins").string());
    dirs.push_back((exe.parent_path().parent_path() / "lib/motionpipe/plugins").string());
  }
  return dirs;
}

}  // namespace motionpipe::worker
