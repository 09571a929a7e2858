// The leg_cleanup plugin: a learned clean-up of generated legs (leg_cleanup.h), trained by the
// train stage on a corpus stage's editing triplets (both sides of each triplet of the split, at
// least `crop` frames long) or on motion files (real mocap: clips, AMASS npz, BVH), and run by the
// clean_legs stage on an edit or generate stage's motions.
//
// Factories: ("model", "leg_cleanup") for the train stage, config: CleanupOptions (width,
// dilations, height, fps, crop, corruption {degrees, shrink, toward_share, toward, warp_share},
// loss {rotation, position, slide}), data: {split: train, val_split: val, limit: 0 (triplets of
// the split; 0 = all), triplets: a directory with triplet files (an earlier job's corpus result)
// instead of the inputs, motions: motion files or directories (the last val_fraction, 0.1, of
// each motion validates); CleanupDataset};
// ("generator", "leg_cleanup") loads a checkpoint directory: a request's `source` is the motion to
// clean (texts are not read).
#include "../api/plugin.hpp"

#include <omp.h>
#include <torch/torch.h>

#include "../api/generator.hpp"
#include "../api/model.hpp"
#include "../common/threads.h"
#include "leg_cleanup.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"

namespace motionpipe::legs {

namespace {

class CleanupModel : public plugin::Model {
 public:
  explicit CleanupModel(const nlohmann::json& config)
      : options_(CleanupOptions::FromJson(config)), net_(options_) {}
  std::string Name() const override { return "leg_cleanup"; }
  torch::nn::Module& Module() override { return *net_; }
  nlohmann::json Config() const override { return options_.ToJson(); }
  std::unique_ptr<plugin::Dataset> MakeDataset(const plugin::DataContext& context) override {
    return std::make_unique<CleanupDataset>(options_, context, files_);
  }
  std::map<std::string, torch::Tensor> Losses(const plugin::Batch& batch, int64_t) override {
    Window w;
    w.trans = batch.tensors.at("trans");
    w.given_trans = batch.tensors.at("given_trans");
    w.r0 = batch.tensors.at("r0");
    w.legs = batch.tensors.at("legs");
    w.noisy = batch.tensors.at("noisy");
    return CleanupLosses(net_, w, options_);
  }
  CleanupNet& net() { return net_; }
  const CleanupOptions& options() const { return options_; }

 private:
  CleanupOptions options_;
  CleanupNet net_;
  // The training and validation datasets crop the same files: each is read once.
  std::shared_ptr<CleanupFiles> files_ = std::make_shared<CleanupFiles>();
};

// Cleans the legs of the requests' source motions with a trained checkpoint.
class CleanupGenerator : public plugin::Generator {
 public:
  explicit CleanupGenerator(const std::string& dir) {
    auto text = ReadFile(layout::ModelConfigFile(dir));
    if (!text.ok()) throw std::invalid_argument(text.status().message());
    model_ = std::make_unique<CleanupModel>(nlohmann::json::parse(*text).at("config"));
    torch::serialize::InputArchive archive;
    archive.load_from(layout::ModelWeightsFile(dir));
    model_->Module().load(archive);
    model_->Module().eval();
  }
  std::string Name() const override { return "leg_cleanup"; }
  Result<Motion> Generate(const plugin::GenerateRequest& request) override {
    if (!request.source) return InvalidArgument("leg_cleanup cleans a motion: give it as source");
    nn::SetTorchThreads(omp_get_max_threads());
    try {
      return CleanLegs(model_->net(), model_->options(), *request.source);
    } catch (const std::exception& e) {
      return InvalidArgument(std::string("leg_cleanup: ") + e.what());
    }
  }

 private:
  std::unique_ptr<CleanupModel> model_;
};

const mp_object_factory kFactories[] = {
    {"model", "leg_cleanup",
     [](const char* config, char* error, size_t size) {
       return plugin::CreateFromJson("leg_cleanup", config, error, size,
                                     [](const nlohmann::json& c) -> void* {
                                       return static_cast<plugin::Model*>(new CleanupModel(c));
                                     });
     },
     [](void* object) { delete static_cast<plugin::Model*>(object); }},
    {"generator", "leg_cleanup",
     [](const char* config, char* error, size_t size) {
       return plugin::CreateFromJson(
           "leg_cleanup", config, error, size, [](const nlohmann::json& c) -> void* {
             return static_cast<plugin::Generator*>(
                 new CleanupGenerator(c.at("checkpoint").get<std::string>()));
           });
     },
     [](void* object) { delete static_cast<plugin::Generator*>(object); }},
};

const mp_plugin kPlugin = {MOTIONPIPE_PLUGIN_ABI_VERSION,
                           sizeof(mp_plugin),
                           "leg_cleanup",
                           "1.0.0",
                           0,
                           nullptr,
                           2,
                           kFactories};

}  // namespace

}  // namespace motionpipe::legs

extern "C" __attribute__((visibility("default"))) const mp_plugin* motionpipe_plugin_v1(void) {
  return &motionpipe::legs::kPlugin;
}
