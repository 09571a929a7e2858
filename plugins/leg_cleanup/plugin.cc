// The leg_cleanup plugin: a learned clean-up of generated legs (leg_cleanup.h), trained by the
// train stage on a corpus stage's editing triplets (both sides of each triplet of the split, at
// least `crop` frames long) and run by the clean_legs stage on an edit or generate stage's motions.
//
// Factories: ("model", "leg_cleanup") for the train stage, config: CleanupOptions (width,
// dilations, height, fps, crop, corruption {degrees, shrink, toward_share, toward, warp_share},
// loss {rotation, position, slide}), data: {split: train, limit: 0 (triplets; 0 = all), triplets:
// a directory with triplet files (an earlier job's corpus result) instead of the inputs};
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
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/math/rotation.h"

namespace motionpipe::legs {

namespace {

// Both sides of a split's triplets as training motions, each with its partner (the other side).
class CleanupDataset : public plugin::Dataset {
 public:
  CleanupDataset(const CleanupOptions& options, const plugin::DataContext& context)
      : options_(options) {
    const std::string split = context.config.value("split", context.split);
    const int64_t limit = context.config.value("limit", int64_t{0});
    std::vector<std::string> paths;
    const std::string given = context.config.value("triplets", std::string());
    if (!given.empty()) {
      paths = TripletFilesIn(given);
      if (paths.empty())
        throw std::invalid_argument("leg_cleanup: data.triplets: no triplet files in " + given);
    }
    for (const auto& dir : given.empty() ? context.input_dirs : std::vector<std::string>{}) {
      const std::vector<std::string> found = TripletFilesIn(dir);
      paths.insert(paths.end(), found.begin(), found.end());
      if (!found.empty()) break;  // a corpus's result holds every triplet; its tasks, shards
    }
    if (paths.empty())
      throw std::invalid_argument(
          "leg_cleanup: no triplet files in the inputs (give a corpus stage as input, or "
          "data.triplets)");
    int64_t triplets = 0;
    for (const auto& path : paths) {
      auto columns = ReadTripletColumns(path, {.positions = false});
      if (!columns.ok()) throw std::invalid_argument(columns.status().message());
      const size_t file = files_.size();
      files_.push_back(std::move(*columns));
      const TripletColumns& c = files_.back();
      if (c.source.joints != kNumJoints || c.target.joints != kNumJoints)
        throw std::invalid_argument(c.origin + ": not an SMPL-22 body");
      for (int64_t row = 0; row < c.rows; ++row) {
        if (c.splits[static_cast<size_t>(row)] != split) continue;
        if (std::abs(c.fps[static_cast<size_t>(row)] - options_.fps) > 1e-6) {
          throw std::invalid_argument(c.origin + ": triplet " + c.ids[static_cast<size_t>(row)] +
                                      " at " + std::to_string(c.fps[static_cast<size_t>(row)]) +
                                      " fps; the clean-up trains at " +
                                      std::to_string(options_.fps));
        }
        for (bool source : {true, false}) {
          if (Frames(file, row, source) >= options_.crop) items_.push_back({file, row, source});
        }
        if (limit > 0 && ++triplets >= limit) break;
      }
      if (limit > 0 && triplets >= limit) break;
    }
    if (items_.empty())
      throw std::invalid_argument("leg_cleanup: no motions of " + std::to_string(options_.crop) +
                                  " frames or more in split '" + split + "' of the inputs");
  }

  int64_t size() const override { return static_cast<int64_t>(items_.size()); }

  plugin::Batch Get(const std::vector<int64_t>& indices, uint64_t seed) override {
    auto generator = at::make_generator<at::CPUGeneratorImpl>(seed);
    const auto b = static_cast<int64_t>(indices.size());
    const int64_t t = options_.crop;
    // Filled as plain arrays (element-wise tensor indexing would cost more than the step's net).
    std::vector<float> trans_v(static_cast<size_t>(b * t * 3)),
        r0_v(static_cast<size_t>(b * t * 9));
    std::vector<float> legs_v(static_cast<size_t>(b * t * 54)), partner_v(legs_v.size());
    for (int64_t i = 0; i < b; ++i) {
      const Item& item = items_.at(static_cast<size_t>(indices[static_cast<size_t>(i)]));
      const int64_t frames = Frames(item.file, item.row, item.source);
      const int64_t start = torch::randint(0, frames - t + 1, {1}, generator).item<int64_t>();
      const int64_t partner_frames = Frames(item.file, item.row, !item.source);
      for (int64_t f = 0; f < t; ++f) {
        const auto at = static_cast<size_t>(i * t + f);
        const float* pose = Pose(item.file, item.row, item.source, start + f);
        Write(&r0_v[at * 9], pose);
        const float* other =
            Pose(item.file, item.row, !item.source, std::min(start + f, partner_frames - 1));
        for (size_t k = 0; k < kLegJoints.size(); ++k) {
          Write(&legs_v[(at * 6 + k) * 9], pose + 3 * kLegJoints[k]);
          Write(&partner_v[(at * 6 + k) * 9], other + 3 * kLegJoints[k]);
        }
        const float* x = Trans(item.file, item.row, item.source, start + f);
        for (size_t c = 0; c < 3; ++c) trans_v[at * 3 + c] = x[c];
      }
    }
    const auto trans = torch::from_blob(trans_v.data(), {b, t, 3}).clone();
    const auto r0 = torch::from_blob(r0_v.data(), {b, t, 3, 3}).clone();
    const auto legs = torch::from_blob(legs_v.data(), {b, t, 6, 3, 3}).clone();
    const auto partner = torch::from_blob(partner_v.data(), {b, t, 6, 3, 3});
    plugin::Batch batch;
    batch.size = b;
    batch.tensors["noisy"] = Corrupt(legs, partner, options_, generator);
    auto given = trans;
    if (options_.height) {
      given = trans.clone();
      given.select(-1, 2).add_(HeightDrift(b, t, generator));
    }
    batch.tensors["trans"] = trans;
    batch.tensors["given_trans"] = given;
    batch.tensors["r0"] = r0;
    batch.tensors["legs"] = legs;
    return batch;
  }

 private:
  struct Item {
    size_t file = 0;
    int64_t row = 0;
    bool source = true;
  };
  const TripletColumns::Side& SideOf(size_t file, bool source) const {
    return source ? files_[file].source : files_[file].target;
  }
  int64_t Frames(size_t file, int64_t row, bool source) const {
    const auto& o = SideOf(file, source).offsets;
    return o[static_cast<size_t>(row) + 1] - o[static_cast<size_t>(row)];
  }
  const float* Pose(size_t file, int64_t row, bool source, int64_t frame) const {
    const auto& s = SideOf(file, source);
    return s.poses + (s.offsets[static_cast<size_t>(row)] + frame) * s.joints * 3;
  }
  const float* Trans(size_t file, int64_t row, bool source, int64_t frame) const {
    const auto& s = SideOf(file, source);
    return s.trans + (s.offsets[static_cast<size_t>(row)] + frame) * 3;
  }
  // The rotation matrix (row-major) of an axis-angle triple.
  static void Write(float* to, const float* axis_angle) {
    const Mat3 r = AxisAngleToMatrix({axis_angle[0], axis_angle[1], axis_angle[2]});
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) to[i * 3 + j] = static_cast<float>(r[i][j]);
    }
  }

  CleanupOptions options_;
  std::vector<TripletColumns> files_;
  std::vector<Item> items_;
};

class CleanupModel : public plugin::Model {
 public:
  explicit CleanupModel(const nlohmann::json& config)
      : options_(CleanupOptions::FromJson(config)), net_(options_) {}
  std::string Name() const override { return "leg_cleanup"; }
  torch::nn::Module& Module() override { return *net_; }
  nlohmann::json Config() const override { return options_.ToJson(); }
  std::unique_ptr<plugin::Dataset> MakeDataset(const plugin::DataContext& context) override {
    return std::make_unique<CleanupDataset>(options_, context);
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
