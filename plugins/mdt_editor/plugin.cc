// The mdt_editor plugin: SimMotionEdit's MDT and the diffusion baselines TMED and MDM (MDM-BP is
// MDM sampled with body-part inpainting), trained by the train stage on editing triplets, and a
// generator that edits motions with a trained checkpoint (DDPM or DDIM, three-way classifier-free
// guidance).
//
// Factories: ("model", "mdt_editor") for the train stage; ("generator", "mdt_editor") loads a
// checkpoint directory; {"body_parts": true} runs an MDM checkpoint as MDM-BP.
#include "../api/plugin.hpp"

#include <omp.h>
#include <torch/torch.h>

#include <filesystem>
#include <iterator>
#include <map>

#include "../api/generator.hpp"
#include "../api/model.hpp"
#include "../common/threads.h"
#include "edit_data.h"
#include "editor.h"
#include "foot_contact.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/features/anchor.h"
#include "motionpipe/features/motionfix207.h"
#include "motionpipe/labels/labeler.h"
#include "motionpipe/motion/foot_lock.h"
#include "motionpipe/motion/plausibility.h"

namespace motionpipe::mdt {

namespace {

class EditorModel : public plugin::Model {
 public:
  explicit EditorModel(const nlohmann::json& config)
      : config_(config),
        options_(EditorOptions::FromJson(config)),
        schedule_(options_.diffusion_steps, options_.snr_shift) {
    net_ = EditorNet(options_);
    mean_ = net_->register_buffer("feature_mean", torch::zeros({kEditFeatureDim}));
    std_ = net_->register_buffer("feature_std", torch::ones({kEditFeatureDim}));
    if (options_.leg_weight != 1) leg_columns_ = LegColumnWeights(options_.leg_weight);
  }

  std::string Name() const override { return "mdt_editor"; }
  torch::nn::Module& Module() override { return *net_; }
  nlohmann::json Config() const override { return options_.ToJson(); }

  std::unique_ptr<plugin::Dataset> MakeDataset(const plugin::DataContext& context) override {
    EditDataOptions data = EditDataOptions::FromContext(context);
    data.classes = options_.classes;
    data.fps = options_.fps;
    data.regression = options_.aux == "regression";
    auto dataset = std::make_unique<EditDataset>(data, context.input_dirs);
    if (context.split == "train") {
      auto encoder = net_->text_encoder();
      if (!options_.text_encoder_from.empty() && !encoder->fitted()) {
        const std::string dir = nn::LoadPretrainedTextEncoder(
            encoder, options_.text_encoder_from, context.input_dirs, options_.freeze_text_encoder);
        if (context.rank == 0) {
          std::fprintf(stderr, "mdt_editor: text encoder from %s (%s)\n", dir.c_str(),
                       options_.freeze_text_encoder ? "frozen" : "fine-tuned");
        }
      }
      if (!encoder->fitted())
        nn::FitShared(encoder, dataset->AllTexts(), context.state_dir, context.rank);
      if (!stats_ready_) {
        auto [mean, stddev] = dataset->ComputeStats();
        mean_.copy_(mean);
        std_.copy_(stddev);
        if (options_.components > 0) {
          const double explained = net_->FitFrameBasis(dataset->FrameCovariance(mean, stddev));
          if (context.rank == 0) {
            std::fprintf(stderr,
                         "mdt_editor: diffusion on %lld principal components of the 207-d frame "
                         "(%.2f%% of its variance)\n",
                         static_cast<long long>(options_.components), 100 * explained);
          }
        }
        stats_ready_ = true;
      }
    }
    dataset->SetStats(mean_, std_);
    return dataset;
  }

  std::map<std::string, torch::Tensor> Losses(const plugin::Batch& batch, int64_t) override {
    const auto& target = batch.tensors.at("target");
    const int64_t n = target.size(1), frames = target.size(0);
    // Per example: the diffusion step, the noise and the condition dropout, from the example's seed
    // when the trainer gives one (the same draws on any rank), else from torch's generator.
    std::vector<int64_t> steps(static_cast<size_t>(n));
    std::vector<torch::Tensor> noise;
    std::vector<uint8_t> drop_text(static_cast<size_t>(n)), drop_source(static_cast<size_t>(n));
    const auto seeds = batch.tensors.find("example_seed");
    for (int64_t i = 0; i < n; ++i) {
      auto generator = seeds != batch.tensors.end()
                           ? at::make_generator<at::CPUGeneratorImpl>(
                                 static_cast<uint64_t>(seeds->second[i].item<int64_t>()))
                           : at::make_generator<at::CPUGeneratorImpl>(static_cast<uint64_t>(
                                 torch::randint(1LL << 62, {1}).item<int64_t>()));
      steps[static_cast<size_t>(i)] =
          SampleTrainingStep(schedule_.steps(), options_.step_density_power, generator);
      const double u = torch::rand({1}, generator).item<double>();
      const bool both = u < options_.drop_both;
      drop_text[static_cast<size_t>(i)] =
          both || (u >= options_.drop_both && u < options_.drop_both + options_.drop_text);
      drop_source[static_cast<size_t>(i)] =
          both || (u >= options_.drop_both + options_.drop_text &&
                   u < options_.drop_both + options_.drop_text + options_.drop_source);
      noise.push_back(torch::randn({frames, net_->diffusion_dim()}, generator));
    }
    const auto t = torch::tensor(steps, torch::kInt64);
    const auto xt = schedule_.QSample(net_->Encode(target), t, torch::stack(noise, 1));
    Condition c;
    c.texts = batch.texts;
    c.drop_text =
        torch::tensor(std::vector<int64_t>(drop_text.begin(), drop_text.end())).to(torch::kBool);
    if (options_.uses_source()) {
      c.source = batch.tensors.at("source");
      c.source_padding = batch.tensors.at("source_padding");
      c.drop_source = torch::tensor(std::vector<int64_t>(drop_source.begin(), drop_source.end()))
                          .to(torch::kBool);
    }
    Prediction p = net_->forward(xt, t, batch.tensors.at("target_padding"), c);
    p.x0 = net_->Decode(p.x0);  // the loss is on the 207-d frame whatever the diffusion's space
    std::map<std::string, torch::Tensor> out;
    out["x0"] = GroupedMaskedMse(p.x0, target, batch.tensors.at("target_padding"),
                                 options_.min_snr_gamma > 0
                                     ? MinSnrWeights(schedule_, t, options_.min_snr_gamma)
                                     : torch::Tensor(),
                                 leg_columns_);
    auto loss = out["x0"];
    if (options_.velocity_weight > 0) {
      out["velocity"] = VelocityMse(p.x0, target, batch.tensors.at("target_padding"));
      loss = loss + options_.velocity_weight * out["velocity"];
    }
    if (options_.foot_contact_weight > 0 || options_.foot_velocity_weight > 0 ||
        p.contacts.defined()) {
      // The geometric losses read metres: the features' normalisation undone (REFERENCE.md 2).
      const auto scale = NormalisationScale(std_);
      const auto predicted = p.x0 * scale + mean_, actual = target * scale + mean_;
      const auto& padding = batch.tensors.at("target_padding");
      const double fps = options_.fps > 0 ? options_.fps : 30.0;
      if (p.contacts.defined()) {
        out["contacts"] = ContactLoss(
            p.contacts, ContactLabels(actual, fps, PlausibilityOptions{}.skate_speed), padding);
        loss = loss + options_.contacts_weight * out["contacts"];
      }
      if (options_.foot_contact_weight > 0) {
        out["foot_contact"] =
            FootContactLoss(predicted, actual, padding, fps, PlausibilityOptions{}.skate_speed);
        loss = loss + options_.foot_contact_weight * out["foot_contact"];
      }
      if (options_.foot_velocity_weight > 0) {
        out["foot_velocity"] = FootVelocityLoss(predicted, actual, padding, fps);
        loss = loss + options_.foot_velocity_weight * out["foot_velocity"];
      }
    }
    if (p.similarity.defined()) {
      const auto aux =
          SimilarityLoss(p.similarity, batch.tensors.at("classes"), batch.tensors.at("similarity"),
                         c.source_padding, c.drop_source, options_);
      out.insert(aux.begin(), aux.end());
      loss = loss + options_.aux_weight * out["aux"];
    }
    out["loss"] = loss;
    return out;
  }

  void SaveExtras(const std::string& dir) const override { net_->text_encoder()->SaveExtras(dir); }
  void LoadExtras(const std::string& dir) override {
    net_->text_encoder()->LoadExtras(dir);
    stats_ready_ = true;
  }

  EditorNet net() const { return net_; }
  const EditorOptions& options() const { return options_; }
  const CosineSchedule& schedule() const { return schedule_; }
  torch::Tensor mean() const { return mean_; }
  torch::Tensor stddev() const { return std_; }

 private:
  nlohmann::json config_;
  EditorOptions options_;
  CosineSchedule schedule_;
  EditorNet net_{nullptr};
  torch::Tensor mean_, std_;
  torch::Tensor leg_columns_;  // the x0 loss's column weights with loss.legs, undefined at 1
  bool stats_ready_ = false;
};

// Edits motions with a trained checkpoint.
class EditorGenerator : public plugin::Generator {
 public:
  EditorGenerator(const std::string& dir, const nlohmann::json& options) {
    auto text = ReadFile(layout::ModelConfigFile(dir));
    if (!text.ok()) throw std::invalid_argument(text.status().message());
    model_ = std::make_unique<EditorModel>(nlohmann::json::parse(*text).at("config"));
    model_->LoadExtras(dir);
    torch::serialize::InputArchive archive;
    archive.load_from(layout::ModelWeightsFile(dir));
    model_->Module().load(archive);
    model_->Module().eval();
    body_parts_ = options.value("body_parts", false);
    if (body_parts_ && model_->options().variant != "mdm")
      throw std::invalid_argument("body_parts (MDM-BP) runs mdm checkpoints");
    labeler_ = options.value("labeler", std::string("lexicon"));
    // The guidance scales g_m, g_t (three-way) or g_t (MDM): the checkpoint's unless given.
    guidance_motion_ = options.value("guidance_motion", model_->options().guidance_motion);
    guidance_text_ = options.value("guidance_text", model_->options().guidance_text);
    // > 0: guidance only at diffusion steps t >= this one, the fully conditional estimate (g = 1)
    // below: Kynkaanniemi et al. 2024's guidance interval, not in the paper. Tried because text
    // guidance adds about a tenth of contact frames to the MDT's skate; measured (issue 15), the
    // clean steps' guidance is also what moves the edits towards their targets, so 0 stays.
    guidance_from_step_ = options.value("guidance_from_step", int64_t{0});
    if (guidance_from_step_ < 0 || guidance_from_step_ > model_->schedule().steps())
      throw std::invalid_argument("guidance_from_step must be in [0, " +
                                  std::to_string(model_->schedule().steps()) + "]");
    // How an edit made at the network's own rate (`fps`) is brought to the source's: linear
    // (slerp and lerp, the default) or cubic (a Catmull-Rom spline through the network's frames;
    // motion.h). Not in the paper, whose network runs at 30 fps (issue 15: the jerk the upsampling
    // adds).
    auto upsample =
        ParseUpsampling(options.value("upsample", std::string("linear")), "edit option upsample");
    if (!upsample.ok()) throw std::invalid_argument(upsample.status().message());
    upsample_ = *upsample;
    // > 0: DDIM starts from the aligned source noised to this step (SDEdit), not from pure noise.
    start_step_ = options.value("start_step", int64_t{0});
    if (start_step_ < 0 || start_step_ >= model_->schedule().steps())
      throw std::invalid_argument("start_step must be in [0, " +
                                  std::to_string(model_->schedule().steps() - 1) + "]");
    if (start_step_ > 0 && !model_->options().uses_source())
      throw std::invalid_argument("start_step starts from the source: an mdt or tmed checkpoint");
    // foot_lock: {below_step: t, ...}: PhysDiff's projection (Yuan et al. 2023; not in the
    // paper) with foot locking (motion/foot_lock.h) as the projection: each x0 estimate at a
    // step below t is decoded, its feet planted and encoded back, so that the later steps build
    // on planted feet. plant: false does the decoding and encoding only (the control). The other
    // keys are foot_lock's (FootLockOptionsFromJson; an unknown key is an error), applied at the
    // network's frame rate.
    //
    // foot_lock: {contacts: predicted, ...}: the edit, decoded at the rate asked for, has its feet
    // planted (LockFeet) where the checkpoint's contact head (loss.contacts) says they stand in
    // the last estimate, instead of where the post-process's height and speed test guesses
    // (issue 15; not in the paper). contacts: test (the default) is that test;
    // predicted_near_floor holds the head's calls only where the foot joint is below the
    // contact height (at any speed: the test's dragged feet), predicted_or_test those and every
    // frame the test holds.
    const nlohmann::json lock = options.value("foot_lock", nlohmann::json::object());
    auto lock_options =
        FootLockOptionsFromJson(lock, "foot_lock", {"below_step", "plant", "contacts"});
    if (!lock_options.ok()) throw std::invalid_argument(lock_options.status().message());
    foot_lock_ = *lock_options;
    foot_lock_below_step_ = lock.value("below_step", int64_t{0});
    plant_feet_ = lock.value("plant", true);
    if (foot_lock_below_step_ < 0 || foot_lock_below_step_ > model_->schedule().steps())
      throw std::invalid_argument("foot_lock.below_step must be in [0, " +
                                  std::to_string(model_->schedule().steps()) + "]");
    const std::string contacts = lock.value("contacts", std::string("test"));
    const std::map<std::string, GivenContacts> rules = {
        {"predicted", GivenContacts::kAlone},
        {"predicted_near_floor", GivenContacts::kNearFloor},
        {"predicted_or_test", GivenContacts::kNearFloorOrTest}};
    if (contacts != "test" && rules.count(contacts) == 0) {
      std::string known = "test";
      for (auto rule = rules.begin(); rule != rules.end(); ++rule)
        known += (std::next(rule) == rules.end() ? " or " : ", ") + rule->first;
      throw std::invalid_argument("foot_lock.contacts must be " + known + " (got '" + contacts +
                                  "')");
    }
    lock_predicted_ = contacts != "test";
    if (lock_predicted_) foot_lock_.given = rules.at(contacts);
    if (lock_predicted_ && !(model_->options().contacts_weight > 0))
      throw std::invalid_argument("foot_lock.contacts " + contacts +
                                  " needs a checkpoint trained with a contact head "
                                  "(loss.contacts > 0)");
    if (lock_predicted_ && foot_lock_below_step_ > 0)
      throw std::invalid_argument("foot_lock: contacts " + contacts +
                                  " plants the edit once; below_step plants the estimates "
                                  "inside the sampler: one or the other");
  }

  std::string Name() const override {
    return "mdt_editor/" + (body_parts_ ? std::string("mdm_bp") : model_->options().variant);
  }

  Result<Motion> Generate(const plugin::GenerateRequest& request) override {
    MP_ASSIGN_OR_RETURN(auto motions, GenerateBatch({request}));
    return std::move(motions.front());
  }

  Result<std::vector<Motion>> GenerateBatch(
      const std::vector<plugin::GenerateRequest>& requests) override {
    if (requests.empty()) return std::vector<Motion>{};
    nn::SetTorchThreads(
        omp_get_max_threads());  // the calling task's budget, for torch and the BLAS
    try {
      return Edit(requests);
    } catch (const std::exception& e) {
      return InvalidArgument(std::string("edit: ") + e.what());
    }
  }

 private:
  // MDM-BP: a projection of each x0 estimate that gives back the source's values for the body
  // parts its edit text does not involve (`source`: [T, n, 207], normalised, at the target length).
  Result<Projection> KeepUneditedParts(const std::vector<std::string>& texts,
                                       const torch::Tensor& source) const {
    const auto n = static_cast<int64_t>(texts.size());
    auto labeler = labels::MakeBuiltinLabeler(labeler_, nlohmann::json::object());
    if (!labeler.ok()) return labeler.status();
    std::vector<labels::LabelInput> asks;
    for (const auto& t : texts) asks.push_back({t, nullptr});
    MP_ASSIGN_OR_RETURN(const auto parts, (*labeler)->Label(asks));
    const auto columns = PartColumns();
    auto keep = torch::zeros({1, n, kEditFeatureDim}, torch::kBool);
    for (int64_t i = 0; i < n; ++i) {
      const PartSet edited = parts[static_cast<size_t>(i)];
      if (edited == 0) continue;  // nothing recognised: the whole body may change
      for (int p = 0; p < kNumBodyParts; ++p) {
        if (!(edited & (1u << p))) keep[0][i].logical_or_(columns[p]);
      }
      // A joint shared by edited and kept parts (none in SMPL-22's partition) would stay edited.
      for (int p = 0; p < kNumBodyParts; ++p) {
        if (edited & (1u << p)) keep[0][i].logical_and_(columns[p].logical_not());
      }
    }
    const auto net = model_->net();
    return Projection([keep, source, net](const torch::Tensor& x0, int64_t) {
      return net->Encode(torch::where(keep, source, net->Decode(x0)));
    });
  }

  // The foot-lock projection of x0 estimates [T, n, D] at steps below foot_lock_below_step_:
  // each edit's first `lengths[i]` frames decoded (at `rates[i]`, placed at `anchors[i]`), its
  // feet planted and encoded back; padding frames as they were.
  Projection PlantFeet(const std::vector<MotionAnchor>& anchors, const std::vector<double>& rates,
                       const std::vector<int64_t>& lengths, const torch::Tensor& scale) const {
    const auto net = model_->net();
    const torch::Tensor mean = model_->mean();
    return [=, below = foot_lock_below_step_, options = foot_lock_, plant = plant_feet_](
               const torch::Tensor& x0, int64_t t) {
      if (t >= below) return x0;
      auto features = (net->Decode(x0) * scale + mean).contiguous();  // [T, n, 207]
      for (size_t i = 0; i < lengths.size(); ++i) {
        const int64_t frames = lengths[i];
        FeatureMatrix f(frames, kEditFeatureDim);
        const auto fi =
            features.select(1, static_cast<int64_t>(i)).narrow(0, 0, frames).contiguous();
        std::memcpy(f.data.data(), fi.data_ptr<float>(),
                    sizeof(float) * static_cast<size_t>(frames * kEditFeatureDim));
        Motion m = DecodeMotionFix207(f, anchors[i], rates[i]);
        if (plant) m = LockFeet(Skeleton::Smpl22(), m, options);
        FeatureMatrix back = EditFeatures(m, nullptr);
        if (back.rows != frames) throw std::logic_error("foot_lock: features changed length");
        features.select(1, static_cast<int64_t>(i))
            .narrow(0, 0, frames)
            .copy_(torch::from_blob(back.data.data(), {frames, kEditFeatureDim}));
      }
      return net->Encode((features - mean) / scale);
    };
  }

  // A batch's texts, its sources (normalised, padded along time with their last frame) and its
  // lengths, at the network's rate and as asked.
  struct EditBatch {
    std::vector<std::string> texts;
    std::vector<int64_t> lengths;                          // at the network's rate
    std::vector<int64_t> requested;                        // at the request's rate
    torch::Tensor source, source_padding, target_padding;  // [ts, n, d], [n, ts], [n, tt]
    int64_t tt = 0;                                        // the longest edit's network frames
  };

  Result<EditBatch> Batch(const std::vector<plugin::GenerateRequest>& requests) const {
    const EditorOptions& o = model_->options();
    const auto n = static_cast<int64_t>(requests.size());
    const auto scale = NormalisationScale(model_->stddev());
    EditBatch batch;
    std::vector<torch::Tensor> sources;
    std::vector<int64_t>& lengths = batch.lengths;
    std::vector<std::string>& texts = batch.texts;
    for (const auto& r : requests) {
      if (r.texts.size() != 1) return InvalidArgument("an edit takes one instruction text");
      if (r.sampler != requests[0].sampler || r.steps != requests[0].steps)
        return InvalidArgument("a batch shares its sampler and steps");
      texts.push_back(r.texts[0]);
      if ((o.uses_source() || body_parts_) && !r.source)
        return InvalidArgument(Name() + " edits a source motion: give one");
      if (r.source) {
        if (r.source->num_frames() < 2)
          return InvalidArgument("the source motion needs at least 2 frames");
        // At the data's own rate (fps 0) the source is encoded as it is, without a copy.
        const FeatureMatrix f =
            o.fps > 0 ? EditFeatures(ToNetworkRate(*r.source, nullptr, o.fps).motion, nullptr)
                      : EditFeatures(*r.source, nullptr);
        sources.push_back(
            (torch::from_blob(const_cast<float*>(f.data.data()), {f.rows, f.cols}).clone() -
             model_->mean()) /
            scale);
      }
      int64_t frames = r.frames > 0 ? r.frames
                       : r.source   ? r.source->num_frames()
                                    : std::lround(r.seconds * r.fps);
      if (body_parts_) frames = r.source->num_frames();  // inpainting keeps the source's timing
      if (frames < 2 || frames > 10000)
        return InvalidArgument(std::to_string(frames) + " frames is not a sensible length");
      batch.requested.push_back(frames);
      // MDM-BP's inpainting keeps the source's frames, at the network's rate too.
      lengths.push_back(body_parts_
                            ? sources.back().size(0)
                            : FramesCovering(frames, r.source ? r.source->fps : r.fps, o.fps));
    }
    const int64_t tt = batch.tt = *std::max_element(lengths.begin(), lengths.end());
    torch::Tensor& target_padding = batch.target_padding = torch::zeros({n, tt}, torch::kBool);
    for (int64_t i = 0; i < n; ++i) {
      if (lengths[static_cast<size_t>(i)] < tt)
        target_padding[i]
            .narrow(0, lengths[static_cast<size_t>(i)], tt - lengths[static_cast<size_t>(i)])
            .fill_(true);
    }
    torch::Tensor& source = batch.source;
    torch::Tensor& source_padding = batch.source_padding;
    if (!sources.empty()) {
      int64_t ts = 1;
      for (const auto& s : sources) ts = std::max(ts, s.size(0));
      source = torch::empty({ts, n, kEditFeatureDim});
      source_padding = torch::zeros({n, ts}, torch::kBool);
      for (int64_t i = 0; i < n; ++i) {
        const auto& s = sources[static_cast<size_t>(i)];
        source.select(1, i).narrow(0, 0, s.size(0)).copy_(s);
        if (s.size(0) < ts) {
          source.select(1, i)
              .narrow(0, s.size(0), ts - s.size(0))
              .copy_(s[s.size(0) - 1].expand({ts - s.size(0), kEditFeatureDim}));
          source_padding[i].narrow(0, s.size(0), ts - s.size(0)).fill_(true);
        }
      }
    }
    return batch;
  }

  // The sampled features x [tt, n, diffusion dim] as motions at their requests' rates and lengths;
  // with the contact head's probabilities `stands`, each planted where they say.
  Result<std::vector<Motion>> DecodeEdits(torch::Tensor x, const torch::Tensor& stands,
                                          const EditBatch& batch,
                                          const std::vector<plugin::GenerateRequest>& requests) {
    const EditorOptions& o = model_->options();
    const auto n = static_cast<int64_t>(requests.size());
    const auto scale = NormalisationScale(model_->stddev());
    const std::vector<int64_t>& lengths = batch.lengths;
    const std::vector<int64_t>& requested = batch.requested;
    x = (model_->net()->Decode(x) * scale + model_->mean()).contiguous();
    std::vector<Motion> out;
    for (int64_t i = 0; i < n; ++i) {
      const int64_t frames = lengths[static_cast<size_t>(i)];
      FeatureMatrix features(frames, kEditFeatureDim);
      const auto xi = x.select(1, i).narrow(0, 0, frames).contiguous();
      std::memcpy(features.data.data(), xi.data_ptr<float>(),
                  sizeof(float) * static_cast<size_t>(frames * kEditFeatureDim));
      const auto& r = requests[static_cast<size_t>(i)];
      const MotionAnchor anchor = r.source ? AnchorOf(*r.source) : MotionAnchor{};
      const double rate = r.source ? r.source->fps : r.fps;
      Motion m = DecodeMotionFix207(features, anchor, o.fps > 0 ? o.fps : rate);
      if (o.fps > 0) {
        MP_ASSIGN_OR_RETURN(
            m, ResampleToFrames(m, rate, requested[static_cast<size_t>(i)], upsample_));
      }
      for (float v : m.poses) {
        if (!std::isfinite(v)) return Internal("edit: the model produced NaN");
      }
      if (stands.defined()) {
        const auto held =
            ContactsAtRate(stands.select(1, i).narrow(0, 0, frames), o.fps, rate, m.num_frames());
        FootLockReport one;
        m = LockFeet(Skeleton::Smpl22(), m, foot_lock_, &one, &held);
        planted_.Add(one);
      }
      out.push_back(std::move(m));
    }
    return out;
  }

  Result<std::vector<Motion>> Edit(const std::vector<plugin::GenerateRequest>& requests) {
    torch::NoGradGuard no_grad;
    const EditorOptions& o = model_->options();
    const auto n = static_cast<int64_t>(requests.size());
    const auto scale = NormalisationScale(model_->stddev());
    MP_ASSIGN_OR_RETURN(const EditBatch batch, Batch(requests));
    const std::vector<std::string>& texts = batch.texts;
    const std::vector<int64_t>& lengths = batch.lengths;
    const torch::Tensor &source = batch.source, &source_padding = batch.source_padding,
                        &target_padding = batch.target_padding;
    const int64_t tt = batch.tt;
    // A condition for branches stacked along the batch, each keeping or dropping the text and the
    // source (1 drops) for all n edits.
    const auto stacked = [&](const std::vector<int>& drop_text,
                             const std::vector<int>& drop_source) {
      const int64_t count = static_cast<int64_t>(drop_text.size());
      const auto flags = [&](const std::vector<int>& per_branch) {
        std::vector<int64_t> v;
        for (int flag : per_branch) v.insert(v.end(), static_cast<size_t>(n), flag);
        return torch::tensor(v).to(torch::kBool);
      };
      Condition stack;
      for (int64_t b = 0; b < count; ++b)
        stack.texts.insert(stack.texts.end(), texts.begin(), texts.end());
      stack.drop_text = flags(drop_text);
      if (o.uses_source()) {
        stack.source = source.repeat({1, count, 1});
        stack.source_padding = source_padding.repeat({count, 1});
        stack.drop_source = flags(drop_source);
      }
      return stack;
    };
    // The guidance branches in one batch: mdt/tmed [u; c_m; c_tm], mdm [u; c_t].
    const int64_t branches = o.uses_source() ? 3 : 2;
    const Condition c = o.uses_source() ? stacked({1, 1, 0}, {1, 0, 0}) : stacked({1, 0}, {});
    const auto padding = target_padding.repeat({branches, 1});
    const Denoise denoise = [&](const torch::Tensor& xt, int64_t t) {
      const auto x0 = model_->net()
                          ->forward(xt.repeat({1, branches, 1}),
                                    torch::full({branches * n}, t, torch::kInt64), padding, c)
                          .x0;
      const auto parts = x0.chunk(branches, 1);
      const bool guided = t >= guidance_from_step_;
      const double g_m = guided ? guidance_motion_ : 1, g_t = guided ? guidance_text_ : 1;
      if (branches == 3) return GuideThreeWay(parts[0], parts[1], parts[2], g_m, g_t);
      return parts[0] + g_t * (parts[1] - parts[0]);
    };
    Projection project;
    if (body_parts_) {
      MP_ASSIGN_OR_RETURN(project, KeepUneditedParts(texts, source.narrow(0, 0, tt)));
    }
    if (foot_lock_below_step_ > 0) {
      std::vector<MotionAnchor> anchors;
      std::vector<double> rates;
      for (const auto& r : requests) {
        anchors.push_back(r.source ? AnchorOf(*r.source) : MotionAnchor{});
        rates.push_back(o.fps > 0 ? o.fps : (r.source ? r.source->fps : r.fps));
      }
      project = [keep = project, plant = PlantFeet(anchors, rates, lengths, scale)](
                    const torch::Tensor& x0, int64_t t) {
        return plant(keep ? keep(x0, t) : x0, t);
      };
    }
    const auto& r0 = requests[0];
    auto generator = at::make_generator<at::CPUGeneratorImpl>(r0.seed);
    const std::vector<int64_t> shape = {tt, n, model_->net()->diffusion_dim()};
    if (start_step_ > 0 && r0.sampler != "ddim")
      return InvalidArgument("start_step needs the ddim sampler (got '" + r0.sampler + "')");
    torch::Tensor x;
    if (r0.sampler.empty() || r0.sampler == "ddpm") {
      x = SampleDdpm(model_->schedule(), shape, denoise, generator, project);
    } else if (r0.sampler == "ddim" && start_step_ > 0) {
      const auto start = model_->net()->Encode(AlignSource(source, source_padding, target_padding));
      x = SampleDdimFromNoised(model_->schedule(), start, start_step_, r0.steps > 0 ? r0.steps : 50,
                               denoise, generator, project);
    } else if (r0.sampler == "ddim") {
      x = SampleDdim(model_->schedule(), shape, r0.steps > 0 ? r0.steps : 50, denoise, generator,
                     project);
    } else {
      return InvalidArgument("sampler must be ddpm or ddim (got '" + r0.sampler + "')");
    }
    torch::Tensor stands;  // [tt, n, 4]: the contact head's probabilities on the last estimate
    if (lock_predicted_) {
      // The head of the fully conditional branch alone (text and source kept), reading the edit
      // itself as a clean x_t (t = 0).
      const Condition full = stacked({0}, {0});
      const auto p =
          model_->net()->forward(x, torch::zeros({n}, torch::kInt64), target_padding, full);
      stands = torch::sigmoid(p.contacts.to(torch::kFloat32)).contiguous();
    }
    return DecodeEdits(x, stands, batch, requests);
  }

  // Sums only, so that an edit stage's tasks add up (the mean shift is planted_shift_m over
  // planted_foot_frames).
  std::vector<std::pair<std::string, double>> Counts() const override {
    if (!lock_predicted_) return {};
    return {{"planted_foot_frames", static_cast<double>(planted_.held)},
            {"planted_runs", static_cast<double>(planted_.runs)},
            {"unreached_ankle_frames", static_cast<double>(planted_.unreached)},
            {"planted_shift_m", planted_.shift}};
  }

  std::unique_ptr<EditorModel> model_;
  bool body_parts_ = false;
  int64_t start_step_ = 0;
  ResampleMethod upsample_ = ResampleMethod::kInterpolate;
  int64_t guidance_from_step_ = 0;
  FootLockOptions foot_lock_;
  int64_t foot_lock_below_step_ = 0;
  bool plant_feet_ = true;
  bool lock_predicted_ = false;
  FootLockReport planted_;  // what the contact head's planting held, over every edit so far
  std::string labeler_;
  double guidance_motion_ = 2, guidance_text_ = 2;
};

const mp_object_factory kFactories[] = {
    {"model", "mdt_editor",
     [](const char* config, char* error, size_t size) {
       return plugin::CreateFromJson("mdt_editor", config, error, size,
                                     [](const nlohmann::json& c) -> void* {
                                       return static_cast<plugin::Model*>(new EditorModel(c));
                                     });
     },
     [](void* object) { delete static_cast<plugin::Model*>(object); }},
    {"generator", "mdt_editor",
     [](const char* config, char* error, size_t size) {
       return plugin::CreateFromJson(
           "mdt_editor", config, error, size, [](const nlohmann::json& c) -> void* {
             return static_cast<plugin::Generator*>(
                 new EditorGenerator(c.at("checkpoint").get<std::string>(), c));
           });
     },
     [](void* object) { delete static_cast<plugin::Generator*>(object); }},
};

const mp_plugin kPlugin = {MOTIONPIPE_PLUGIN_ABI_VERSION,
                           sizeof(mp_plugin),
                           "mdt_editor",
                           "1.0.0",
                           0,
                           nullptr,
                           2,
                           kFactories};

}  // namespace

}  // namespace motionpipe::mdt

extern "C" __attribute__((visibility("default"))) const mp_plugin* motionpipe_plugin_v1(void) {
  return &motionpipe::mdt::kPlugin;
}
