// Where a trained editor's error comes from (issue 15): a checkpoint's x0 error by diffusion step,
// beside what copying the source and predicting the mean would score, and its sampled edits' error
// against target and source in the normalised feature space, with their roughness; and the foot
// skate of the decoded estimates, with what columns of the t = 0 estimate it comes from; along each
// DDIM trajectory (guidance 1/1 and the model's), every step's x0 estimate's error, roughness and
// skate: whether the sample's skate is laid out at the noisy steps or made at the clean ones. A
// checkpoint with a contact head (loss.contacts) also has the head's calls scored against the
// target's own still feet (ContactLabels) by step.
//   mdt_probe <checkpoint dir> <filter/corpus dir>... [--split test] [--n 64] [--ddim 20]
//             [--guidance g_m,g_t] [--no-sample] [--write DIR] [--filter none] [--limit N]
// --filter none reads every triplet of the corpus directories (the filter's kept ones otherwise);
// --limit N takes the n triplets from the split's first N only (the training data's `limit`: the
// triplets a model was fitted to).
// --write DIR also writes, as edit stages eval_edit can score (DIR/NAME/task-00000/edited.npz, at
// the targets' lengths and rates), the targets through the feature and the network's frame rate
// (target_roundtrip), the sources aligned to them as the network reads them (source_aligned), and
// the x0 estimates from each target noised to step t (estimate_tT): what the judges make of the
// network's own reconstruction of the answer.
#include <torch/torch.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "../plugins/common/threads.h"
#include "../plugins/mdt_editor/edit_data.h"
#include "../plugins/mdt_editor/editor.h"
#include "../plugins/mdt_editor/foot_contact.h"
#include "bench_util.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/features/anchor.h"
#include "motionpipe/features/motionfix207.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/motion/plausibility.h"

using namespace motionpipe;
using namespace motionpipe::mdt;

namespace {

// Masked mean squared error per example [N] over frames present in both (lengths may differ).
torch::Tensor Mse(const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& padding) {
  const int64_t t = std::min(a.size(0), b.size(0));
  const auto keep = padding.narrow(1, 0, t).logical_not().t().unsqueeze(2).to(torch::kFloat32);
  return ((a.narrow(0, 0, t) - b.narrow(0, 0, t)).pow(2) * keep).sum(std::vector<int64_t>{0, 2}) /
         (keep.sum(std::vector<int64_t>{0, 2}) * a.size(2)).clamp_min(1);
}

// Mean squared second difference over time per example [N].
torch::Tensor Roughness(const torch::Tensor& x, const torch::Tensor& padding) {
  const auto d2 = x.narrow(0, 2, x.size(0) - 2) - 2 * x.narrow(0, 1, x.size(0) - 2) +
                  x.narrow(0, 0, x.size(0) - 2);
  const auto keep =
      padding.narrow(1, 2, x.size(0) - 2).logical_not().t().unsqueeze(2).to(torch::kFloat32);
  return (d2.pow(2) * keep).sum(std::vector<int64_t>{0, 2}) /
         (keep.sum(std::vector<int64_t>{0, 2}) * x.size(2)).clamp_min(1);
}

struct Args {
  std::vector<std::string> dirs;  // the checkpoint, then the filter/corpus directories
  std::string split = "test", filter = "input";
  int64_t n = 64, ddim = 20, limit = 0;
  bool sample = true, rank = false;
  double g_m = -1, g_t = -1;
  std::string write;  // a directory for the decoded estimates, or empty
};

std::optional<Args> ParseArgs(int argc, char** argv) {
  Args args;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--split" && i + 1 < argc)
      args.split = argv[++i];
    else if (a == "--n" && i + 1 < argc)
      args.n = std::stoll(argv[++i]);
    else if (a == "--filter" && i + 1 < argc)
      args.filter = argv[++i];
    else if (a == "--limit" && i + 1 < argc)
      args.limit = std::stoll(argv[++i]);
    else if (a == "--ddim" && i + 1 < argc)
      args.ddim = std::stoll(argv[++i]);
    else if (a == "--no-sample")
      args.sample = false;
    else if (a == "--rank")
      args.rank = true;
    else if (a == "--guidance" && i + 1 < argc)
      std::sscanf(argv[++i], "%lf,%lf", &args.g_m, &args.g_t);
    else if (a == "--write" && i + 1 < argc)
      args.write = argv[++i];
    else
      args.dirs.push_back(a);
  }
  if (args.dirs.size() < 2) return std::nullopt;
  return args;
}

// The checkpoint's editor with its feature statistics, and n triplets of the split.
struct Probe {
  EditorOptions options;
  EditorNet net{nullptr};
  torch::Tensor mean, stddev;
  plugin::Batch batch;
  Condition c;  // the batch's condition, nothing dropped
  int64_t n = 0;
  std::shared_ptr<EditDataset> dataset;
  std::vector<int64_t> indices;  // the batch's items of the dataset
};

Result<Probe> LoadProbe(const Args& a) {
  Probe probe;
  const std::string checkpoint = a.dirs[0];
  MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(layout::ModelConfigFile(checkpoint)));
  probe.options = EditorOptions::FromJson(nlohmann::json::parse(text).at("config"));
  probe.net = EditorNet(probe.options);
  probe.mean = probe.net->register_buffer("feature_mean", torch::zeros({kEditFeatureDim}));
  probe.stddev = probe.net->register_buffer("feature_std", torch::ones({kEditFeatureDim}));
  probe.net->text_encoder()->LoadExtras(checkpoint);
  torch::serialize::InputArchive archive;
  archive.load_from(layout::ModelWeightsFile(checkpoint));
  probe.net->load(archive);
  probe.net->eval();
  EditDataOptions data;
  data.split = a.split;
  data.filter = a.filter;
  data.limit = a.limit;
  // Written estimates are whole motions; the probe's figures keep the first 120 network frames.
  data.max_frames = a.write.empty() ? 120 : 100000;
  data.fps = probe.options.fps;  // the checkpoint's network rate
  probe.dataset = std::make_shared<EditDataset>(
      data, std::vector<std::string>(a.dirs.begin() + 1, a.dirs.end()));
  EditDataset& dataset = *probe.dataset;
  dataset.SetStats(probe.mean, probe.stddev);
  probe.n = std::min<int64_t>(a.n, dataset.size());
  std::vector<int64_t>& indices = probe.indices;
  for (int64_t i = 0; i < probe.n; ++i) indices.push_back(i * dataset.size() / probe.n);
  probe.batch = dataset.Get(indices, 0);
  probe.c.texts = probe.batch.texts;
  probe.c.source = probe.batch.tensors.at("source");
  probe.c.source_padding = probe.batch.tensors.at("source_padding");
  probe.c.drop_text = torch::zeros({probe.n}, torch::kBool);
  probe.c.drop_source = torch::zeros({probe.n}, torch::kBool);
  return probe;
}

// What copying the source and predicting the mean score, in all and per feature group (frame i
// against frame i).
void PrintYardsticks(const Probe& p) {
  const auto& target = p.batch.tensors.at("target");
  const auto& source = p.batch.tensors.at("source");
  const auto& padding = p.batch.tensors.at("target_padding");
  std::printf("copy source: x0 MSE %.4f   mean (zeros): %.4f\n",
              Mse(source, target, padding).mean().item<double>(),
              Mse(torch::zeros_like(target), target, padding).mean().item<double>());
  for (const auto& g : MotionFixFeatureGroups()) {
    const auto slice = [&](const torch::Tensor& x) {
      return x.narrow(2, g.begin, g.end - g.begin);
    };
    std::printf(
        "  copy source, %-22s MSE %.4f (mean: %.4f)\n", g.name,
        Mse(slice(source), slice(target), padding).mean().item<double>(),
        Mse(torch::zeros_like(slice(target)), slice(target), padding).mean().item<double>());
  }
}

// The foot skate of normalised 207-d frames [T, N, 207] (the target's lengths), decoded at the
// network's rate with every frame grounded (its lowest foot joint moved onto the floor, as
// tools/root_stats.py's "skate grounded": the decoded height's drift does not count): the mean over
// the examples of the fraction of contact foot-frames sliding faster than 0.15 m/s.
double GroundedSkate(const Probe& p, const torch::Tensor& x) {
  const auto frames_of = p.batch.tensors.at("target_padding").logical_not().sum(1);
  const auto raw = (x.to(torch::kFloat32) * NormalisationScale(p.stddev) + p.mean).contiguous();
  const double fps = p.options.fps > 0 ? p.options.fps : 30.0;
  const Skeleton& skeleton = Skeleton::Smpl22();
  double sum = 0;
  for (int64_t i = 0; i < p.n; ++i) {
    const int64_t frames = frames_of[i].item<int64_t>();
    FeatureMatrix features(frames, kMotionFixFeatureDim);
    const auto xi = raw.select(1, i).narrow(0, 0, frames).contiguous();
    std::memcpy(features.data.data(), xi.data_ptr<float>(),
                sizeof(float) * static_cast<size_t>(frames * kMotionFixFeatureDim));
    std::vector<float> joints = ComputeJoints(skeleton, DecodeMotionFix207(features, {}, fps));
    for (int64_t f = 0; f < frames; ++f) {
      float* frame = joints.data() + f * kNumJoints * 3;
      float lowest = frame[skeleton.left_foot_joints()[0] * 3 + 2];
      for (const auto& side : {skeleton.left_foot_joints(), skeleton.right_foot_joints()})
        for (int joint : side) lowest = std::min(lowest, frame[joint * 3 + 2]);
      for (int joint = 0; joint < kNumJoints; ++joint) frame[joint * 3 + 2] -= lowest;
    }
    sum += EvaluatePlausibility(skeleton, joints.data(), frames, fps, nullptr).foot_skate_ratio;
  }
  return sum / static_cast<double>(std::max<int64_t>(p.n, 1));
}

// x with the columns of `from` in `columns` ([begin, end) pairs).
torch::Tensor WithColumns(torch::Tensor x, const torch::Tensor& from,
                          const std::vector<std::pair<int64_t, int64_t>>& columns) {
  x = x.clone();
  for (const auto& [begin, end] : columns)
    x.narrow(2, begin, end - begin).copy_(from.narrow(2, begin, end - begin));
  return x;
}

// Where the t = 0 estimate's skate comes from: its skate with the target's pelvis velocity, the
// target's leg rotations (hips, knees, ankles, feet), or both put back, and the target's with
// only those of the estimate.
void PrintSkateSources(const Probe& p, const torch::Tensor& estimate) {
  const auto& target = p.batch.tensors.at("target");
  const std::vector<std::pair<int64_t, int64_t>> pelvis = {{0, 3}};
  std::vector<std::pair<int64_t, int64_t>> legs;
  for (int joint : {1, 2, 4, 5, 7, 8, 10, 11})
    legs.emplace_back(15 + (joint - 1) * 6, 15 + joint * 6);
  auto both = legs;
  both.insert(both.begin(), pelvis.begin(), pelvis.end());
  std::printf("t = 0 estimate: foot skate (grounded) %.3f; the target's %.3f\n",
              GroundedSkate(p, estimate), GroundedSkate(p, target));
  for (const auto& [name, columns] :
       std::vector<std::pair<const char*, std::vector<std::pair<int64_t, int64_t>>>>{
           {"pelvis velocity (0:3)", pelvis}, {"leg rotations", legs}, {"both", both}}) {
    std::printf(
        "  %-22s  the estimate with the target's: %.3f   the target with the estimate's: %.3f\n",
        name, GroundedSkate(p, WithColumns(estimate, target, columns)),
        GroundedSkate(p, WithColumns(target, estimate, columns)));
  }
}

// The contact head's calls (probability above 1/2) on the target noised to step t against the
// target's still feet: the share of real foot-joint frames it gets right, and of the still ones
// it calls (recall) and of its calls that are still (precision), beside the share that is still.
void PrintContactHead(Probe& p, const CosineSchedule& schedule) {
  const auto& target = p.batch.tensors.at("target");
  const auto& padding = p.batch.tensors.at("target_padding");
  const double fps = p.options.fps > 0 ? p.options.fps : 30.0;
  const auto labels = ContactLabels(target * NormalisationScale(p.stddev) + p.mean, fps,
                                    PlausibilityOptions{}.skate_speed)
                          .to(torch::kBool);
  const auto real = padding.logical_not().t().unsqueeze(2).expand_as(labels);
  const auto count = [](const torch::Tensor& x) { return x.sum().item<double>(); };
  std::printf("contact head: t, right, recall, precision, still (of %.0f foot-joint frames)\n",
              count(real));
  for (int64_t t : {0L, 30L, 100L, 200L, 299L}) {
    if (t >= p.options.diffusion_steps) continue;
    const auto steps = torch::full({p.n}, t, torch::kInt64);
    const auto xt = schedule.QSample(p.net->Encode(target), steps, torch::randn(target.sizes()));
    const auto called = p.net->forward(xt, steps, padding, p.c).contacts.gt(0.0);
    const double still = count(labels & real), calls = count(called & real);
    const double hits = count(called & labels & real);
    std::printf("  t %3lld: %.3f %.3f %.3f %.3f\n", static_cast<long long>(t),
                count((called == labels) & real) / count(real), hits / std::max(still, 1.0),
                hits / std::max(calls, 1.0), still / count(real));
  }
}

// The x0 estimate's error by diffusion step, with and without text or source, beside x_t scaled.
void PrintX0ByStep(Probe& p, const CosineSchedule& schedule) {
  const auto& target = p.batch.tensors.at("target");
  const auto& padding = p.batch.tensors.at("target_padding");
  // "toward source": the estimate's error along (aligned source - target), as a fraction of it: 0
  // when the estimate keeps nothing of the source it should not, 1 for the copy.
  std::printf("%6s %10s %10s %10s %10s %8s %15s %14s\n", "t", "model", "no text", "no source",
              "x_t/sqrt(a)", "skate", "skate no source", "toward source");
  const auto keep = padding.logical_not().t().unsqueeze(2).to(torch::kFloat32);
  const auto aligned = AlignSource(p.c.source, p.c.source_padding, padding);
  const auto away = (aligned - target) * keep;
  const auto toward_source = [&](const torch::Tensor& x0) {
    return (((x0 - target) * away).sum() / away.pow(2).sum()).item<double>();
  };
  torch::Tensor at_zero;
  for (int64_t t : {0L, 10L, 30L, 60L, 100L, 150L, 200L, 250L, 299L}) {
    if (t >= p.options.diffusion_steps) continue;
    const auto steps = torch::full({p.n}, t, torch::kInt64);
    // The diffusion's coordinates (diffusion.components); estimates are scored as 207-d frames.
    const auto z0 = p.net->Encode(target);
    const auto noise = torch::randn(z0.sizes());
    const auto xt = schedule.QSample(z0, steps, noise);
    const auto estimate = [&](const Condition& condition) {
      return p.net->Decode(p.net->forward(xt, steps, padding, condition).x0);
    };
    const auto x0 = estimate(p.c);
    if (t == 0) at_zero = x0;
    const double model = Mse(x0, target, padding).mean().item<double>();
    Condition no_text = p.c, no_source = p.c;
    no_text.drop_text = torch::ones({p.n}, torch::kBool);
    no_source.drop_source = torch::ones({p.n}, torch::kBool);
    const double without_text = Mse(estimate(no_text), target, padding).mean().item<double>();
    const auto x0_no_source = estimate(no_source);
    const double without_source = Mse(x0_no_source, target, padding).mean().item<double>();
    const double scaled =
        Mse(p.net->Decode(xt / std::sqrt(schedule.alpha_bar()[static_cast<size_t>(t)])), target,
            padding)
            .mean()
            .item<double>();
    std::printf("%6lld %10.4f %10.4f %10.4f %10.4f %8.3f %15.3f %14.3f\n",
                static_cast<long long>(t), model, without_text, without_source, scaled,
                GroundedSkate(p, x0), GroundedSkate(p, x0_no_source), toward_source(x0));
  }
  PrintSkateSources(p, at_zero);
  // Is the estimate's pull toward the source what makes it skate? The target moved the t = 0
  // estimate's fraction of the way to the aligned source (a blend of two motions' legs).
  const double toward = toward_source(at_zero);
  std::printf("  the target moved %.3f of the way to the source: foot skate %.3f\n", toward,
              GroundedSkate(p, target + toward * (aligned - target)));
}

// Sampled edits (DDIM, three-way guidance) at g 1/1, traced, and at (g_m, g_t).
void PrintSampledEdits(Probe& p, const CosineSchedule& schedule, int64_t ddim, double g_m,
                       double g_t) {
  const auto& target = p.batch.tensors.at("target");
  const auto& source = p.batch.tensors.at("source");
  const auto& padding = p.batch.tensors.at("target_padding");
  const int64_t n = p.n;
  Condition three;
  for (int b = 0; b < 3; ++b)
    three.texts.insert(three.texts.end(), p.c.texts.begin(), p.c.texts.end());
  three.source = source.repeat({1, 3, 1});
  three.source_padding = p.c.source_padding.repeat({3, 1});
  const auto flags = [&](std::vector<int> v) {
    std::vector<int64_t> out;
    for (int b = 0; b < 3; ++b)
      out.insert(out.end(), static_cast<size_t>(n), v[static_cast<size_t>(b)]);
    return torch::tensor(out).to(torch::kBool);
  };
  three.drop_text = flags({1, 1, 0});
  three.drop_source = flags({1, 0, 0});
  const auto padding3 = padding.repeat({3, 1});
  for (auto [gm, gt] : std::vector<std::pair<double, double>>{{1, 1}, {g_m, g_t}}) {
    const Denoise denoise = [&](const torch::Tensor& xt, int64_t t) {
      const auto parts = p.net
                             ->forward(xt.repeat({1, 3, 1}), torch::full({3 * n}, t, torch::kInt64),
                                       padding3, three)
                             .x0.chunk(3, 1);
      return GuideThreeWay(parts[0], parts[1], parts[2], gm, gt);
    };
    // The x0 estimate along the trajectory: where does the sample leave the source?
    std::printf(
        "DDIM-%lld trajectory, guidance %.1f/%.1f: step t, x0 estimate -> target MSE, -> source "
        "MSE, roughness, foot skate (grounded)\n",
        static_cast<long long>(ddim), gm, gt);
    const Denoise traced = [&](const torch::Tensor& xt, int64_t t) {
      const auto x0 = denoise(xt, t);
      const auto frame = p.net->Decode(x0);
      std::printf("  t %3lld: %.4f %.4f %.5f %.3f\n", static_cast<long long>(t),
                  Mse(frame, target, padding).mean().item<double>(),
                  Mse(frame, source, padding).mean().item<double>(),
                  Roughness(frame, padding).mean().item<double>(), GroundedSkate(p, frame));
      return x0;
    };
    auto generator = at::make_generator<at::CPUGeneratorImpl>(7);
    const auto x = p.net->Decode(
        SampleDdim(schedule, p.net->Encode(target).sizes(), ddim, traced, generator, nullptr));
    std::printf(
        "DDIM-%lld g_m %.1f g_t %.1f: edit-target MSE %.4f, edit-source %.4f; roughness edit %.5f "
        "target %.5f source %.5f; foot skate (grounded) %.3f\n",
        static_cast<long long>(ddim), gm, gt, Mse(x, target, padding).mean().item<double>(),
        Mse(x, source, padding).mean().item<double>(), Roughness(x, padding).mean().item<double>(),
        Roughness(target, padding).mean().item<double>(),
        Roughness(source, p.c.source_padding).mean().item<double>(), GroundedSkate(p, x));
  }
}

// How many numbers a frame needs for its feet to stand: the targets through a rank-K linear code
// of a frame (their projection onto the top K principal directions of the training split's
// normalised frames, sources and targets, about those frames' mean: the code knows nothing of
// the probed targets), with their x0 MSE and skate.
// A trunk d wide carries each frame as d numbers; if even the best linear code of K = d numbers
// slides, precision is lost in the code, not the training.
Status PrintRankFloor(const Args& a, const Probe& p) {
  EditDataOptions data;
  data.split = "train";
  data.filter = a.filter;
  data.limit = a.limit;
  data.fps = p.options.fps;
  EditDataset train(data, std::vector<std::string>(a.dirs.begin() + 1, a.dirs.end()));
  if (train.size() < 2) return InvalidArgument("--rank: the training split has under 2 triplets");
  constexpr int64_t kTriplets = 2000;  // the covariance's training triplets, at most
  torch::Tensor centre;                // the training frames' mean, normalised
  const auto covariance =
      train.FrameCovariance(p.mean, p.stddev, kTriplets, &centre).to(torch::kFloat64);
  const auto [values, vectors] = torch::linalg_eigh(covariance);  // ascending
  const auto& target = p.batch.tensors.at("target");
  const auto& padding = p.batch.tensors.at("target_padding");
  const auto x = target.to(torch::kFloat64);
  centre = centre.to(torch::kFloat64);
  const double total = values.sum().item<double>();
  std::printf(
      "rank-K code of a frame (the training split's principal directions, %lld triplets):\n"
      "%6s %10s %10s %8s\n",
      static_cast<long long>(std::min<int64_t>(train.size(), kTriplets)), "K", "variance", "x0 MSE",
      "skate");
  for (int64_t k : {16L, 32L, 64L, 96L, 128L, 160L, 192L, 207L}) {
    const auto v = vectors.narrow(1, kEditFeatureDim - k, k);  // the K largest
    const auto coded = centre + torch::matmul(torch::matmul(x - centre, v), v.t());
    const auto as_float = coded.to(torch::kFloat32);
    std::printf("%6lld %10.4f %10.4f %8.3f\n", static_cast<long long>(k),
                values.narrow(0, kEditFeatureDim - k, k).sum().item<double>() / total,
                Mse(as_float, target, padding).mean().item<double>(), GroundedSkate(p, as_float));
  }
  return Status::Ok();
}

// Normalised 207-d frames [T, N, 207] at the network's rate as the batch's motions: decoded from
// each target's first frame (as the editor decodes from its source's) and resampled to the
// target's own frame count and rate, written as an edit stage's output (dir/task-00000/edited.npz).
Status WriteMotions(const Probe& p, const torch::Tensor& x, const std::string& dir,
                    const std::string& what) {
  const auto frames_of = p.batch.tensors.at("target_padding").logical_not().sum(1);
  const auto raw = (x.to(torch::kFloat32) * NormalisationScale(p.stddev) + p.mean).contiguous();
  std::vector<Clip> clips;
  for (int64_t i = 0; i < p.n; ++i) {
    const int64_t index = p.indices[static_cast<size_t>(i)];
    const Motion target = p.dataset->SideMotionOf(index, false);
    const int64_t frames = frames_of[i].item<int64_t>();
    FeatureMatrix features(frames, kMotionFixFeatureDim);
    const auto xi = raw.select(1, i).narrow(0, 0, frames).contiguous();
    std::memcpy(features.data.data(), xi.data_ptr<float>(),
                sizeof(float) * static_cast<size_t>(frames * kMotionFixFeatureDim));
    const double rate = p.options.fps > 0 ? p.options.fps : target.fps;
    Motion m = DecodeMotionFix207(features, AnchorOf(target), rate);
    MP_ASSIGN_OR_RETURN(m, ResampleToFrames(m, target.fps, target.num_frames()));
    Clip clip;
    clip.id = p.dataset->Id(index);
    clip.source = "mdt_probe:" + what;
    clip.motion = std::move(m);
    clips.push_back(std::move(clip));
  }
  std::error_code ec;
  std::filesystem::create_directories(dir + "/task-00000", ec);
  if (ec) return Internal(dir + ": cannot create (" + ec.message() + ")");
  return WriteClips(dir + "/task-00000/edited.npz", clips);
}

// The targets through the feature and the network's rate, and the x0 estimates from each target
// noised to step t (t = 0: the clean target as x_t), for eval_edit.
Status WriteEstimates(Probe& p, const CosineSchedule& schedule, const std::string& dir) {
  const auto& target = p.batch.tensors.at("target");
  const auto& padding = p.batch.tensors.at("target_padding");
  MP_RETURN_IF_ERROR(WriteMotions(p, target, dir + "/target_roundtrip", "target_roundtrip"));
  // The source as the network sees it beside its target (AlignSource: the "toward source"
  // direction), decoded from the target's first frame: its leg rotations against the estimates'.
  MP_RETURN_IF_ERROR(WriteMotions(p, AlignSource(p.c.source, p.c.source_padding, padding),
                                  dir + "/source_aligned", "source_aligned"));
  const auto z0 = p.net->Encode(target);
  for (int64_t t : {0L, 60L, 150L, 200L, 250L, 299L}) {
    if (t >= p.options.diffusion_steps) continue;
    const auto steps = torch::full({p.n}, t, torch::kInt64);
    const auto xt = schedule.QSample(z0, steps, torch::randn(z0.sizes()));
    const auto x0 = p.net->Decode(p.net->forward(xt, steps, padding, p.c).x0);
    const std::string name = "estimate_t" + std::to_string(t);
    MP_RETURN_IF_ERROR(WriteMotions(p, x0, dir + "/" + name, name));
  }
  std::printf(
      "wrote %lld motions each to %s/{target_roundtrip,source_aligned,estimate_tT} (T = 0, 60, "
      "150, 200, 250, 299)\n",
      static_cast<long long>(p.n), dir.c_str());
  return Status::Ok();
}

}  // namespace

int main(int argc, char** argv) {
  bench::UseNativeBlasKernels(argv);
  const std::optional<Args> args = ParseArgs(argc, argv);
  if (!args) {
    std::fprintf(
        stderr,
        "usage: mdt_probe <checkpoint dir> <filter dir>... [--split S] [--n N] [--ddim K] "
        "[--guidance gm,gt] [--no-sample] [--rank] [--write DIR] [--filter none] [--limit N]\n");
    return 2;
  }
  nn::SetTorchThreads(1);
  torch::manual_seed(0);
  auto probe = LoadProbe(*args);
  if (!probe.ok()) return std::fprintf(stderr, "%s\n", probe.status().message().c_str()), 1;
  const double g_m = args->g_m < 0 ? probe->options.guidance_motion : args->g_m;
  const double g_t = args->g_m < 0 ? probe->options.guidance_text : args->g_t;
  const CosineSchedule schedule(probe->options.diffusion_steps, probe->options.snr_shift);
  torch::NoGradGuard no_grad;
  std::printf(
      "%s split, %lld triplets, %lld diffusion steps; normalised features (data variance about "
      "0.25)\n",
      args->split.c_str(), static_cast<long long>(probe->n),
      static_cast<long long>(probe->options.diffusion_steps));
  PrintYardsticks(*probe);
  PrintX0ByStep(*probe, schedule);
  if (probe->options.contacts_weight > 0) PrintContactHead(*probe, schedule);
  if (args->sample) PrintSampledEdits(*probe, schedule, args->ddim, g_m, g_t);
  if (args->rank) {
    const Status ranked = PrintRankFloor(*args, *probe);
    if (!ranked.ok()) return std::fprintf(stderr, "%s\n", ranked.message().c_str()), 1;
  }
  if (!args->write.empty()) {
    const Status written = WriteEstimates(*probe, schedule, args->write);
    if (!written.ok()) return std::fprintf(stderr, "%s\n", written.message().c_str()), 1;
  }
  return 0;
}
