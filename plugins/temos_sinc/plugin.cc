// The temos_sinc plugin: TEMOS trained the SINC way, its baselines and TMR, as one model kind with
// variants, and a generator that runs a trained checkpoint.
//
//   variant  sinc        one text (the pair text when there are two actions), the SINC data mix
//            ste         SINC-STE: each action text encoded apart, joined by a learned separator
//            single      the single-action baseline: trained on singles only; pairs are asked with
//            "while" compositing the single-action model + GPT-compositing at generation: each
//            action generated
//                        alone, then composed with the labeler's body parts (SINC sec. 4.2)
//            tmr         the TMR evaluator/text-encoder pre-training: TEMOS + contrastive InfoNCE
//
// Factories: ("model", "temos_sinc") for the train stage; ("generator", "temos_sinc") loads a
// checkpoint directory written by the train stage.
#include "../api/plugin.hpp"

#include <omp.h>
#include <torch/torch.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "../api/generator.hpp"
#include "../api/model.hpp"
#include "../common/threads.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/features/temos135.h"
#include "motionpipe/labels/labeler.h"
#include "motionpipe/sinc/composition.h"
#include "motionpipe/sinc/texts.h"
#include "sinc_data.h"
#include "temos.h"

namespace motionpipe::temos {

namespace {

namespace fs = std::filesystem;

class SincModel : public plugin::Model {
 public:
  explicit SincModel(const nlohmann::json& config) : config_(config) {
    variant_ = config.value("variant", std::string("sinc"));
    if (variant_ != "sinc" && variant_ != "ste" && variant_ != "single" &&
        variant_ != "compositing" && variant_ != "tmr") {
      throw std::invalid_argument("variant must be sinc, ste, single, compositing or tmr (got '" +
                                  variant_ + "')");
    }
    nlohmann::json model = config.value("model", nlohmann::json::object());
    if (variant_ == "ste") model["separate_texts"] = true;
    if (variant_ == "tmr" && !model.contains("contrastive")) model["contrastive"] = 0.1;
    net_ = Temos(TemosOptions::FromJson(model));
    // The network's frame rate (0: the data's). Not in the papers (TEMOS and SINC run at 30 fps):
    // issue 15, a bf16 step at 10 fps is 2.3 times cheaper than one at 30 (README "SINC at 10
    // fps"), so the same time gives each motion that many more views; generation comes back to
    // the asked rate by interpolation.
    fps_ = config.value("fps", 0.0);
    if (!(fps_ >= 0 && fps_ <= kMaxFrameRate))
      throw std::invalid_argument("fps must be in [0, 1000] (0: the data's own rate)");
    mean_ = net_->register_buffer("feature_mean", torch::zeros({kFeatureDim}));
    std_ = net_->register_buffer("feature_std", torch::ones({kFeatureDim}));
  }

  std::string Name() const override { return "temos_sinc"; }
  torch::nn::Module& Module() override { return *net_; }
  nlohmann::json Config() const override {
    nlohmann::json c = config_;
    c["model"] = net_->options().ToJson();
    c["variant"] = variant_;
    return c;
  }

  std::unique_ptr<plugin::Dataset> MakeDataset(const plugin::DataContext& context) override {
    SincDataOptions options = SincDataOptions::FromContext(context);
    options.fps = fps_;
    if (variant_ == "single" || variant_ == "compositing") {
      // The single-action baselines never see two actions at once.
      options.real_pairs = false;
      options.synthetic_p = 0;
    }
    auto table = sinc::ReadSpans(options.spans);
    if (!table.ok()) throw std::invalid_argument(table.status().message());
    auto shared = std::make_shared<sinc::SpanTable>(std::move(*table));
    auto dataset = std::make_unique<SincDataset>(shared, options);
    if (context.split == "train") {
      const std::string from = config_.value("text_encoder_from", std::string());
      if (!from.empty()) LoadPretrainedTextEncoder(from, context);
      if (!net_->text_encoder()->fitted()) FitTextEncoder(*dataset, context);
      if (!stats_ready_) {
        auto [mean, stddev] = dataset->ComputeStats();
        mean_.copy_(mean);
        std_.copy_(stddev);
        stats_ready_ = true;
      }
    }
    dataset->SetStats(mean_, std_);
    return dataset;
  }

  std::map<std::string, torch::Tensor> Losses(const plugin::Batch& batch, int64_t) override {
    std::vector<std::vector<std::string>> texts;
    if (net_->options().separate_texts) {
      texts = batch.groups;
    } else {
      for (const auto& t : batch.texts) texts.push_back({t});
    }
    const auto seeds = batch.tensors.find("example_seed");
    return net_->Losses(texts, batch.tensors.at("features"), batch.tensors.at("padding"),
                        seeds == batch.tensors.end() ? torch::Tensor() : seeds->second);
  }

  void SaveExtras(const std::string& dir) const override { net_->text_encoder()->SaveExtras(dir); }
  void LoadExtras(const std::string& dir) override {
    net_->text_encoder()->LoadExtras(dir);
    stats_ready_ = true;  // the statistics come with the weights
  }

  Temos net() { return net_; }
  const std::string& variant() const { return variant_; }
  double fps() const { return fps_; }
  torch::Tensor mean() const { return mean_; }
  torch::Tensor stddev() const { return std_; }

 private:
  // The text encoder (tokenizer + transformer) of a pre-trained checkpoint, TMR-style contrastive
  // (REFERENCE 5), frozen unless freeze_text_encoder is false: the role DistilBERT/CLIP play in
  // the papers. `from` is a checkpoint directory, or "input" for the stage input that is one.
  void LoadPretrainedTextEncoder(const std::string& from, const plugin::DataContext& context) {
    const bool freeze = config_.value("freeze_text_encoder", true);
    auto encoder = net_->text_encoder();
    const std::string dir =
        nn::LoadPretrainedTextEncoder(encoder, from, context.input_dirs, freeze);
    if (context.rank == 0)
      std::fprintf(stderr, "temos_sinc: text encoder from %s (%s)\n", dir.c_str(),
                   freeze ? "frozen" : "fine-tuned");
  }

  void FitTextEncoder(const SincDataset& dataset, const plugin::DataContext& context) {
    auto encoder = net_->text_encoder();
    nn::FitShared(encoder, dataset.AllTexts(), context.state_dir, context.rank);
  }

  nlohmann::json config_;
  std::string variant_;
  double fps_ = 0;
  Temos net_{nullptr};
  torch::Tensor mean_, std_;
  bool stats_ready_ = false;
};

// Runs a trained checkpoint (torch-free interface for the CLI and evaluators).
class SincGenerator : public plugin::Generator {
 public:
  // options: {"compositing": true} runs a single-action checkpoint as the GPT-compositing baseline;
  // {"reconstruct": true} decodes each request's source motion from the motion encoder's mean
  // (the VAE's reconstruction: what the decoder can give back, beside what the text asks of it).
  SincGenerator(const std::string& dir, const nlohmann::json& options) {
    auto text = ReadFile(layout::ModelConfigFile(dir));
    if (!text.ok()) throw std::invalid_argument(text.status().message());
    const nlohmann::json meta = nlohmann::json::parse(*text);
    model_ = std::make_unique<SincModel>(meta.at("config"));
    model_->LoadExtras(dir);
    torch::serialize::InputArchive archive;
    archive.load_from(layout::ModelWeightsFile(dir));
    model_->Module().load(archive);
    model_->Module().eval();
    compositing_ = model_->variant() == "compositing" || options.value("compositing", false);
    reconstruct_ = options.value("reconstruct", false);
    // How a motion made at the network's own rate is brought to the one asked for: linear (slerp
    // and lerp, the default) or cubic (a Catmull-Rom spline through the network's frames;
    // motion.h). Not in the paper, whose network runs at 30 fps (issue 15).
    auto upsample = ParseUpsampling(options.value("upsample", std::string("linear")),
                                    "generate option upsample");
    if (!upsample.ok()) throw std::invalid_argument(upsample.status().message());
    upsample_ = *upsample;
    if (reconstruct_ && compositing_)
      throw std::invalid_argument("reconstruct and compositing do not go together");
    if (compositing_ && model_->variant() != "single" && model_->variant() != "compositing") {
      throw std::invalid_argument("compositing runs single-action models, this one is '" +
                                  model_->variant() + "'");
    }
  }
  std::string Name() const override {
    return "temos_sinc/" + std::string(compositing_ ? "compositing" : model_->variant()) +
           (reconstruct_ ? " (reconstruction)" : "");
  }

  Result<Motion> Generate(const plugin::GenerateRequest& request) override {
    if (request.texts.empty()) return InvalidArgument("generate: give at least one text");
    const int64_t frames = request.frames > 0
                               ? request.frames
                               : static_cast<int64_t>(std::lround(request.seconds * request.fps));
    if (frames < 2 || frames > 10000)
      return InvalidArgument("generate: " + std::to_string(frames) +
                             " frames is not a sensible duration");
    nn::SetTorchThreads(
        omp_get_max_threads());  // the calling task's budget, for torch and the BLAS
    try {
      torch::NoGradGuard no_grad;
      torch::manual_seed(request.seed);
      if (compositing_ && request.texts.size() > 1) return Compose(request, frames);
      if (reconstruct_) {
        if (!request.source) return InvalidArgument("generate: reconstruct needs a source motion");
        return Reconstruct(*request.source);
      }
      std::vector<std::vector<std::string>> texts;
      if (model_->net()->options().separate_texts) {
        texts = {request.texts};
      } else {
        texts = {{request.texts.size() == 1
                      ? request.texts[0]
                      : sinc::EvalPairText(request.texts[0], request.texts[1])}};
      }
      return DecodeOne(texts, frames, request.fps);
    } catch (const std::exception& e) {
      return InvalidArgument(std::string("generate: ") + e.what());
    }
  }

  Result<std::vector<std::vector<float>>> EncodeMotions(
      const std::vector<Motion>& motions) override {
    torch::NoGradGuard no_grad;
    std::vector<std::vector<float>> out;
    for (const Motion& m : motions) {
      const auto d = EncodeOne(m);
      out.emplace_back(d.mu.data_ptr<float>(), d.mu.data_ptr<float>() + d.mu.numel());
    }
    return out;
  }

  Result<std::vector<std::vector<float>>> EncodeTexts(
      const std::vector<std::string>& texts) override {
    torch::NoGradGuard no_grad;
    std::vector<std::vector<std::string>> groups;
    for (const auto& t : texts) groups.push_back({t});
    const auto d = model_->net()->EncodeText(groups, false);
    std::vector<std::vector<float>> out;
    for (int64_t i = 0; i < d.mu.size(0); ++i)
      out.emplace_back(d.mu[i].data_ptr<float>(), d.mu[i].data_ptr<float>() + d.mu.size(1));
    return out;
  }

 private:
  // The motion encoder's distribution of one motion (at the network's rate: every k-th frame for
  // a whole-number ratio, as in training, else interpolated).
  Distribution EncodeOne(const Motion& motion) const {
    // Only a model at its own rate pays for the copy (the TMR scores every motion through here).
    const bool own_rate = model_->fps() > 0 && !SameFrameRate(motion.fps, model_->fps());
    const Motion resampled = own_rate ? ToModelRate(motion, model_->fps()) : Motion{};
    const Motion& m = own_rate ? resampled : motion;
    const int64_t frames = m.num_frames();
    std::vector<float> features(static_cast<size_t>(frames * kFeatureDim));
    EncodeTemos135Fast(m.poses.data(), m.trans.data(), frames, features.data());
    auto x = (torch::from_blob(features.data(), {frames, kFeatureDim}).clone() - model_->mean()) /
             (model_->stddev() + 1e-5);
    return model_->net()->EncodeMotion(x.unsqueeze(1), torch::zeros({1, frames}, torch::kBool),
                                       false);
  }

  Result<Motion> Reconstruct(const Motion& source) {
    if (source.num_frames() < 2) return InvalidArgument("generate: a source of under 2 frames");
    return DecodeLatent(EncodeOne(source).mu, source.num_frames(), source.fps);
  }

  Result<Motion> DecodeOne(const std::vector<std::vector<std::string>>& texts, int64_t frames,
                           double fps) {
    return DecodeLatent(model_->net()->EncodeText(texts, false).z, frames, fps);
  }

  // A latent [1, latent] decoded to a motion of `frames` frames at `fps` (made at the network's
  // rate, then interpolated to `fps`).
  Result<Motion> DecodeLatent(const torch::Tensor& z, int64_t frames, double fps) {
    const double rate = model_->fps() > 0 ? model_->fps() : fps;
    const int64_t asked = frames;
    frames = FramesCovering(asked, fps, rate);
    const auto padding = torch::zeros({1, frames}, torch::kBool);
    auto x = model_->net()->Decode(z, padding).select(1, 0);  // [T, 135]
    x = (x * (model_->stddev() + 1e-5) + model_->mean()).contiguous();
    FeatureMatrix features(frames, kFeatureDim);
    std::memcpy(features.data.data(), x.data_ptr<float>(),
                sizeof(float) * static_cast<size_t>(frames * kFeatureDim));
    Motion m = DecodeTemos135(features, CanonicalTemosAnchor(), rate);
    for (float v : m.poses) {
      if (!std::isfinite(v)) return Internal("generate: the model produced NaN");
    }
    if (!SameFrameRate(rate, fps)) return ResampleToFrames(m, fps, asked, upsample_);
    return m;
  }

  // GPT-compositing baseline: each action alone, composed by the labeler's parts.
  Result<Motion> Compose(const plugin::GenerateRequest& request, int64_t frames) {
    auto labeler = labels::MakeBuiltinLabeler(
        model_->Config().value("compositing_labeler", std::string("lexicon")),
        nlohmann::json::object());
    if (!labeler.ok()) return labeler.status();
    MP_ASSIGN_OR_RETURN(const auto parts, (*labeler)->Label({{request.texts[0], nullptr},
                                                             {request.texts[1], nullptr}}));
    MP_ASSIGN_OR_RETURN(const Motion a, DecodeOne({{request.texts[0]}}, frames, request.fps));
    MP_ASSIGN_OR_RETURN(const Motion b, DecodeOne({{request.texts[1]}}, frames, request.fps));
    return sinc::Compose(a, parts[0], b, parts[1], sinc::CropMode::kFirst);
  }

  std::unique_ptr<SincModel> model_;
  bool compositing_ = false;
  bool reconstruct_ = false;
  ResampleMethod upsample_ = ResampleMethod::kInterpolate;
};

const mp_object_factory kFactories[] = {
    {"model", "temos_sinc",
     [](const char* config, char* error, size_t size) {
       return plugin::CreateFromJson("temos_sinc", config, error, size,
                                     [](const nlohmann::json& c) -> void* {
                                       return static_cast<plugin::Model*>(new SincModel(c));
                                     });
     },
     [](void* object) { delete static_cast<plugin::Model*>(object); }},
    {"generator", "temos_sinc",
     [](const char* config, char* error, size_t size) {
       return plugin::CreateFromJson(
           "temos_sinc", config, error, size, [](const nlohmann::json& c) -> void* {
             return static_cast<plugin::Generator*>(
                 new SincGenerator(c.at("checkpoint").get<std::string>(), c));
           });
     },
     [](void* object) { delete static_cast<plugin::Generator*>(object); }},
};

const mp_plugin kPlugin = {MOTIONPIPE_PLUGIN_ABI_VERSION,
                           sizeof(mp_plugin),
                           "temos_sinc",
                           "1.0.0",
                           0,
                           nullptr,
                           2,
                           kFactories};

}  // namespace

}  // namespace motionpipe::temos

extern "C" __attribute__((visibility("default"))) const mp_plugin* motionpipe_plugin_v1(void) {
  return &motionpipe::temos::kPlugin;
}
