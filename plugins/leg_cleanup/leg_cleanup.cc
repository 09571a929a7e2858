#include "leg_cleanup.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <tuple>

#include "motionpipe/formats/clip.h"
#include "motionpipe/math/rotation.h"
#include "motionpipe/motion/plausibility.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::legs {

namespace F = torch::nn::functional;
using torch::indexing::Ellipsis;
using torch::indexing::Slice;

namespace {

double Radians(double degrees) { return degrees * M_PI / 180.0; }

// Uniform draws [shape] in [0, 1).
torch::Tensor Uniform(const std::vector<int64_t>& shape, at::Generator& generator) {
  return torch::rand(shape, generator);
}

// The rest offsets (y-up body frame) of the leg chains' joints, [22, 3] (zeros elsewhere).
const torch::Tensor& RestOffsets() {
  static const torch::Tensor offsets = [] {
    const auto& rest = Skeleton::Smpl22().rest_offsets();
    auto t = torch::zeros({kNumJoints, 3});
    for (int j = 0; j < kNumJoints; ++j) {
      for (int c = 0; c < 3; ++c) t[j][c] = rest[static_cast<size_t>(j)][c];
    }
    return t;
  }();
  return offsets;
}

// The index of joint `joint` in kLegJoints.
int64_t LegIndex(int joint) {
  for (size_t k = 0; k < kLegJoints.size(); ++k) {
    if (kLegJoints[k] == joint) return static_cast<int64_t>(k);
  }
  throw std::logic_error("not a leg joint");
}

// The yaw (radians) of the body's forward axis (its y-up rest frame's z) in the z-up world.
torch::Tensor Heading(const torch::Tensor& r0) {
  const auto forward = r0.index({Ellipsis, Slice(), 2});
  return torch::atan2(forward.index({Ellipsis, 1}), forward.index({Ellipsis, 0}));
}

torch::Tensor YawMatrix(const torch::Tensor& angle) {
  const auto c = torch::cos(angle), s = torch::sin(angle);
  const auto zero = torch::zeros_like(c), one = torch::ones_like(c);
  auto shape = angle.sizes().vec();
  shape.push_back(3);
  shape.push_back(3);
  return torch::stack({c, -s, zero, s, c, zero, zero, zero, one}, -1).reshape(shape);
}

// Frame differences along dim 1 with the last one repeated (the same length as x).
torch::Tensor ForwardDifference(const torch::Tensor& x) {
  const int64_t t = x.size(1);
  const auto d = x.narrow(1, 1, t - 1) - x.narrow(1, 0, t - 1);
  return torch::cat({d, d.narrow(1, t - 2, 1)}, 1);
}

}  // namespace

CleanupOptions CleanupOptions::FromJson(const nlohmann::json& j) {
  CleanupOptions o;
  o.width = j.value("width", o.width);
  o.dilations = j.value("dilations", o.dilations);
  o.height = j.value("height", o.height);
  o.fps = j.value("fps", o.fps);
  o.crop = j.value("crop", o.crop);
  const nlohmann::json c = j.value("corruption", nlohmann::json::object());
  o.degrees = c.value("degrees", o.degrees);
  o.shrink = c.value("shrink", o.shrink);
  o.toward_share = c.value("toward_share", o.toward_share);
  o.toward = c.value("toward", o.toward);
  o.warp_share = c.value("warp_share", o.warp_share);
  const nlohmann::json l = j.value("loss", nlohmann::json::object());
  o.rotation_weight = l.value("rotation", o.rotation_weight);
  o.position_weight = l.value("position", o.position_weight);
  o.slide_weight = l.value("slide", o.slide_weight);
  if (o.width < 1 || o.dilations.empty())
    throw std::invalid_argument("leg_cleanup: width must be positive and dilations not empty");
  for (int64_t d : o.dilations) {
    if (d < 1) throw std::invalid_argument("leg_cleanup: dilations must be positive");
  }
  if (!(o.fps > 0) || o.crop < 8)
    throw std::invalid_argument("leg_cleanup: fps must be positive and crop at least 8 frames");
  for (double share : {o.shrink, o.toward_share, o.warp_share}) {
    if (!(share >= 0 && share <= 1))
      throw std::invalid_argument("leg_cleanup: corruption shares must be in [0, 1]");
  }
  if (!(o.degrees >= 0) || !(o.toward >= 0 && o.toward <= 1))
    throw std::invalid_argument(
        "leg_cleanup: corruption.degrees must be >= 0 and corruption.toward in [0, 1]");
  return o;
}

nlohmann::json CleanupOptions::ToJson() const {
  return {
      {"width", width},
      {"dilations", dilations},
      {"height", height},
      {"fps", fps},
      {"crop", crop},
      {"corruption",
       {{"degrees", degrees},
        {"shrink", shrink},
        {"toward_share", toward_share},
        {"toward", toward},
        {"warp_share", warp_share}}},
      {"loss",
       {{"rotation", rotation_weight}, {"position", position_weight}, {"slide", slide_weight}}}};
}

std::string NumberText(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", value);
  return text;
}

torch::Tensor Rodrigues(const torch::Tensor& v) {
  const auto angle = v.norm(2, -1, true).clamp_min(1e-8);
  const auto k = v / angle;
  const auto zero = torch::zeros_like(k.index({Ellipsis, 0}));
  const auto kx = k.index({Ellipsis, 0}), ky = k.index({Ellipsis, 1}), kz = k.index({Ellipsis, 2});
  auto shape = v.sizes().vec();
  shape.back() = 3;
  shape.push_back(3);
  const auto K = torch::stack({zero, -kz, ky, kz, zero, -kx, -ky, kx, zero}, -1).reshape(shape);
  const auto s = torch::sin(angle).unsqueeze(-1), c = torch::cos(angle).unsqueeze(-1);
  return torch::eye(3, v.options()).expand_as(K) + s * K + (1 - c) * torch::matmul(K, K);
}

torch::Tensor LogMap(const torch::Tensor& r) {
  const auto cos = ((r.diagonal(0, -2, -1).sum(-1) - 1) / 2).clamp(-1 + 1e-6, 1 - 1e-6);
  const auto angle = torch::acos(cos);
  const auto at = [&](int64_t i, int64_t j) { return r.index({Ellipsis, i, j}); };
  const auto axis =
      torch::stack({at(2, 1) - at(1, 2), at(0, 2) - at(2, 0), at(1, 0) - at(0, 1)}, -1);
  return axis * (angle / (2 * torch::sin(angle).clamp_min(1e-6))).unsqueeze(-1);
}

torch::Tensor RootFeatures(const torch::Tensor& trans, const torch::Tensor& r0, double fps) {
  const auto h = Heading(r0);
  const auto unturn = YawMatrix(-h);
  auto velocity = ForwardDifference(trans) * fps;
  velocity = torch::matmul(unturn, velocity.unsqueeze(-1)).squeeze(-1);
  // The heading's change to the next frame (0 at the last), wrapped to [-pi, pi).
  const int64_t t = h.size(1);
  auto turn = torch::cat(
      {h.narrow(1, 1, t - 1) - h.narrow(1, 0, t - 1), torch::zeros_like(h.narrow(1, 0, 1))}, 1);
  turn = torch::remainder(turn + M_PI, 2 * M_PI) - M_PI;
  return torch::cat({trans.index({Ellipsis, Slice(2, 3)}), velocity, (turn * fps).unsqueeze(-1),
                     SixD(torch::matmul(unturn, r0))},
                    -1);
}

torch::Tensor LegPositions(const torch::Tensor& trans, const torch::Tensor& r0,
                           const torch::Tensor& legs) {
  const auto& offsets = RestOffsets();
  const auto offset = [&](int joint) { return offsets[joint].to(trans.dtype()).unsqueeze(-1); };
  std::vector<torch::Tensor> out;
  static const std::array<std::array<int, 4>, 2> chains = nn::LegChains(Skeleton::Smpl22());
  for (const auto& chain : chains) {
    auto world = r0;
    auto position = trans + torch::matmul(r0, offset(chain[0])).squeeze(-1);
    for (size_t k = 1; k < chain.size(); ++k) {
      world = torch::matmul(world, legs.select(2, LegIndex(chain[k - 1])));
      position = position + torch::matmul(world, offset(chain[k])).squeeze(-1);
      out.push_back(position);
    }
  }
  return torch::stack(out, 2);
}

CleanupNetImpl::CleanupNetImpl(const CleanupOptions& options) : height(options.height) {
  const int64_t channels = kRootFeatures + 6 * static_cast<int64_t>(kLegJoints.size());
  const int64_t w = options.width;
  in = register_module(
      "first",
      torch::nn::Conv1d(
          torch::nn::Conv1dOptions(channels, w, 5).padding(2).padding_mode(torch::kReplicate)));
  for (int64_t d : options.dilations) {
    blocks->push_back(
        torch::nn::Conv1d(torch::nn::Conv1dOptions(w, w, 5).padding(2 * d).dilation(d).padding_mode(
            torch::kReplicate)));
  }
  register_module("blocks", blocks);
  out = register_module("last",
                        torch::nn::Conv1d(torch::nn::Conv1dOptions(
                            w, 6 * static_cast<int64_t>(kLegJoints.size()) + (height ? 1 : 0), 1)));
  // The untrained net gives its input back (a zero correction).
  torch::NoGradGuard no_grad;
  out->weight.zero_();
  out->bias.zero_();
}

std::pair<torch::Tensor, torch::Tensor> CleanupNetImpl::forward(const torch::Tensor& root,
                                                                const torch::Tensor& legs) {
  const int64_t b = legs.size(0), t = legs.size(1), joints = legs.size(2);
  const auto legs6 = SixD(legs).reshape({b, t, 6 * joints});
  auto h = in->forward(torch::cat({root, legs6.to(root.dtype())}, -1).transpose(1, 2));
  for (const auto& block : *blocks) h = h + block->as<torch::nn::Conv1d>()->forward(torch::gelu(h));
  const auto delta = out->forward(torch::gelu(h)).transpose(1, 2).to(legs.dtype());
  const auto dz = height ? delta.select(-1, 6 * joints) : torch::zeros({b, t}, legs.options());
  const auto cleaned = legs6 + delta.narrow(-1, 0, 6 * joints);
  return {FromSixD(cleaned.reshape({b, t, joints, 6})), dz};
}

torch::Tensor SmoothNoise(const std::vector<int64_t>& shape, double sigma_frames,
                          at::Generator& generator) {
  auto x = torch::randn(shape, generator);
  const auto radius = static_cast<int64_t>(3 * sigma_frames) + 1;
  auto kernel = torch::arange(-radius, radius + 1, torch::kFloat32) / sigma_frames;
  kernel = torch::exp(-0.5 * kernel * kernel);
  kernel = (kernel / kernel.sum()).reshape({1, 1, -1});
  const int64_t b = shape[0], t = shape[1];
  const int64_t rest = x.numel() / (b * t);
  // [B, T, rest] -> [B * rest, 1, T], filtered along T.
  auto flat = x.reshape({b, t, rest}).permute({0, 2, 1}).reshape({b * rest, 1, t});
  flat = torch::conv1d(F::pad(flat, F::PadFuncOptions({radius, radius}).mode(torch::kReplicate)),
                       kernel);
  flat = flat / flat.std().clamp_min(1e-8);
  return flat.reshape({b, rest, t}).permute({0, 2, 1}).reshape(shape);
}

torch::Tensor Corrupt(const torch::Tensor& legs, const torch::Tensor& partner,
                      const CleanupOptions& options, at::Generator& generator) {
  const int64_t b = legs.size(0), t = legs.size(1), joints = legs.size(2);
  const double radians = Radians(options.degrees);
  // Key noise at every third frame (a 10-fps network's), linear in between, of spread up to
  // `degrees`.
  const int64_t keys = (t + 2) / 3 + 1;
  const auto key_noise = torch::randn({b, keys, joints, 3}, generator);
  const auto frame = torch::arange(t, torch::kFloat32);
  const auto lo = torch::floor(frame / 3).to(torch::kInt64);
  const auto w = (frame - 3 * lo.to(torch::kFloat32)) / 3;
  const auto wv = w.reshape({1, t, 1, 1});
  auto e = key_noise.index_select(1, lo) * (1 - wv) + key_noise.index_select(1, lo + 1) * wv;
  e = radians * Uniform({b, 1, 1, 1}, generator) * e;
  // A slow offset of up to 3x that spread, over 0.1-0.5 s.
  const auto amplitude = 3 * radians * Uniform({b, 1, 1, 1}, generator);
  const double sigma = 3 + 12 * Uniform({1}, generator).item<double>();
  e = e + amplitude * SmoothNoise({b, t, joints, 3}, sigma, generator);
  // Part of the way toward the partner's legs, for a share of the batch.
  const auto toward = (Uniform({b, 1, 1}, generator) < options.toward_share).to(torch::kFloat32) *
                      options.toward * Uniform({b, 1, 1}, generator);
  e = e + toward.unsqueeze(-1) * LogMap(torch::matmul(legs.transpose(-1, -2), partner));
  auto noisy = torch::matmul(legs, Rodrigues(e));
  // The legs' timing warped against the pelvis (rate 0.85-1.15 about the window's middle).
  const auto warp = Uniform({b}, generator) < options.warp_share;
  const auto rate = 0.85 + 0.3 * Uniform({b}, generator);
  // The swing shrunk toward its mean over the window, to 0.2-1 of its range.
  const auto pick = Uniform({b}, generator) < options.shrink;
  const auto scale = 0.2 + 0.8 * Uniform({b}, generator);
  const bool any_warp = warp.any().item<bool>(), any_pick = pick.any().item<bool>();
  if (any_warp || any_pick) {
    auto six = SixD(noisy);  // [B, T, J, 6]
    if (any_warp) {
      const double centre = static_cast<double>(t - 1) / 2;
      const auto src =
          ((frame.unsqueeze(0) - centre) * rate.unsqueeze(1) + centre).clamp(0, t - 1);  // [B, T]
      const auto lo_w = src.floor().to(torch::kInt64);
      const auto hi_w = (lo_w + 1).clamp_max(t - 1);
      const auto ww = (src - lo_w.to(torch::kFloat32)).reshape({b, t, 1, 1});
      const auto gather = [&](const torch::Tensor& idx) {
        return torch::gather(six, 1, idx.reshape({b, t, 1, 1}).expand({b, t, joints, 6}));
      };
      const auto warped = gather(lo_w) * (1 - ww) + gather(hi_w) * ww;
      six = torch::where(warp.reshape({b, 1, 1, 1}), warped, six);
    }
    if (any_pick) {
      const auto mean = six.mean(1, true);
      const auto shrunk = mean + scale.reshape({b, 1, 1, 1}) * (six - mean);
      six = torch::where(pick.reshape({b, 1, 1, 1}), shrunk, six);
    }
    const auto changed = (warp | pick).reshape({b, 1, 1, 1, 1});
    noisy = torch::where(changed, FromSixD(six), noisy);
  }
  return noisy;
}

torch::Tensor HeightDrift(int64_t batch, int64_t frames, at::Generator& generator) {
  const auto u = [&] { return 2 * Uniform({batch, 1}, generator) - 1; };
  const auto ramp = torch::linspace(-0.5, 0.5, frames).unsqueeze(0);
  const double sigma = 10 + 20 * Uniform({1}, generator).item<double>();
  const auto wobble = SmoothNoise({batch, frames}, sigma, generator);
  const auto offset = u();
  const auto drift = u();
  const auto wobble_size = u().abs();
  return 0.05 * offset + 0.15 * drift * ramp + 0.05 * wobble_size * wobble;
}

Result<std::shared_ptr<const TripletColumns>> CleanupFiles::Triplets(const std::string& path) {
  return Once(triplets_, path, [&] { return ReadTripletColumns(path, {.positions = false}); });
}

Result<std::shared_ptr<const std::vector<Motion>>> CleanupFiles::Motions(const std::string& path,
                                                                         double fps) {
  return Once(motions_, std::make_pair(path, fps), [&]() -> Result<std::vector<Motion>> {
    auto clips = LoadMotionFile(path, fps);
    if (!clips.ok()) return clips.status();
    std::vector<Motion> motions;
    for (Clip& clip : *clips) motions.push_back(std::move(clip.motion));
    return motions;
  });
}

CleanupDataset::CleanupDataset(const CleanupOptions& options, const plugin::DataContext& context,
                               std::shared_ptr<CleanupFiles> files)
    : options_(options), files_(files ? std::move(files) : std::make_shared<CleanupFiles>()) {
  const nlohmann::json config =
      context.config.is_object() ? context.config : nlohmann::json::object();
  const bool validation = context.split == "val";
  const bool motions = config.contains("motions");
  // Triplets: data.triplets, else the inputs' unless data.motions names the data alone.
  if (config.contains("triplets") || !motions) {
    // The held-out split for validation (data.val_split, "val"), else data.split ("train").
    AddTriplets(config, context.input_dirs,
                validation ? config.value("val_split", std::string("val"))
                           : config.value("split", std::string("train")));
  }
  if (motions) AddMotions(config, validation);
}

void CleanupDataset::AddTriplets(const nlohmann::json& config,
                                 const std::vector<std::string>& input_dirs,
                                 const std::string& split) {
  const int64_t limit = config.value("limit", int64_t{0});
  std::vector<std::string> paths;
  const std::string given = config.value("triplets", std::string());
  if (!given.empty()) {
    paths = TripletFilesIn(given);
    if (paths.empty())
      throw std::invalid_argument("leg_cleanup: data.triplets: no triplet files in " + given);
  }
  if (given.empty()) paths = StageTripletFiles(input_dirs);  // a corpus's result, not its shards
  if (paths.empty())
    throw std::invalid_argument(
        "leg_cleanup: no triplet files in the inputs (give a corpus stage as input, "
        "data.triplets, or data.motions for motion files)");
  int64_t triplets = 0;
  const size_t first = tracks_.size();
  for (const auto& path : paths) {
    auto columns = files_->Triplets(path);  // the tracks point into the shared columns
    if (!columns.ok()) throw std::invalid_argument(columns.status().message());
    const TripletColumns& c = **columns;
    if (c.source.joints != kNumJoints || c.target.joints != kNumJoints)
      throw std::invalid_argument(c.origin + ": not an SMPL-22 body");
    for (int64_t row = 0; row < c.rows; ++row) {
      const auto r = static_cast<size_t>(row);
      if (c.splits[r] != split) continue;
      if (std::abs(c.fps[r] - options_.fps) > 1e-6) {
        throw std::invalid_argument(c.origin + ": triplet " + c.ids[r] + " at " +
                                    NumberText(c.fps[r]) + " fps; the clean-up trains at " +
                                    NumberText(options_.fps));
      }
      const auto side = [&](const TripletColumns::Side& s) {
        const int64_t at = s.offsets[r];
        return std::make_pair(s.poses + at * kNumJoints * 3, s.trans + at * 3);
      };
      const auto frames = [&](const TripletColumns::Side& s) {
        return s.offsets[r + 1] - s.offsets[r];
      };
      for (bool source : {true, false}) {
        const auto& self = source ? c.source : c.target;
        const auto& other = source ? c.target : c.source;
        if (frames(self) < options_.crop) continue;
        const auto [poses, trans] = side(self);
        tracks_.push_back({poses, trans, frames(self), side(other).first, frames(other)});
      }
      if (limit > 0 && ++triplets >= limit) break;
    }
    if (limit > 0 && triplets >= limit) break;
  }
  if (tracks_.size() == first)
    throw std::invalid_argument("leg_cleanup: no motions of " + std::to_string(options_.crop) +
                                " frames or more in split '" + split + "' of the inputs");
}

void CleanupDataset::AddMotions(const nlohmann::json& config, bool validation) {
  namespace fs = std::filesystem;
  const nlohmann::json& given = config.at("motions");
  std::vector<std::string> named;
  if (given.is_string()) {
    named.push_back(given.get<std::string>());
  } else if (given.is_array() && !given.empty() &&
             std::all_of(given.begin(), given.end(), [](const auto& v) { return v.is_string(); })) {
    for (const auto& v : given) named.push_back(v.get<std::string>());
  } else {
    throw std::invalid_argument(
        "leg_cleanup: data.motions: a file or directory, or a list of them");
  }
  const double fraction = config.value("val_fraction", 0.1);
  if (!(fraction > 0 && fraction < 1))
    throw std::invalid_argument("leg_cleanup: data.val_fraction must be in (0, 1), not " +
                                NumberText(fraction));
  std::vector<std::string> files;
  for (const std::string& path : named) {
    std::error_code error;
    if (fs::is_directory(path, error)) {
      std::vector<std::string> found;
      for (const auto& entry : fs::directory_iterator(path)) {
        const std::string ext = entry.path().extension().string();
        if (entry.is_regular_file() && (ext == ".npz" || ext == ".bvh"))
          found.push_back(entry.path().string());
      }
      if (found.empty())
        throw std::invalid_argument("leg_cleanup: data.motions: no motion files (.npz, .bvh) in " +
                                    path);
      std::sort(found.begin(), found.end());
      files.insert(files.end(), found.begin(), found.end());
    } else if (fs::exists(path, error)) {
      files.push_back(path);
    } else {
      throw std::invalid_argument("leg_cleanup: data.motions: no such file or directory: " + path);
    }
  }
  std::vector<const Motion*> motions;  // the tracks point into the shared motions
  for (const std::string& file : files) {
    auto loaded = files_->Motions(file, options_.fps);
    if (!loaded.ok()) throw std::invalid_argument("leg_cleanup: " + loaded.status().message());
    for (const Motion& m : **loaded) motions.push_back(&m);
  }
  // The part of each motion this split reads: the first (1 - fraction) of its frames for
  // training, the rest for validation.
  const auto part = [&](size_t i) {
    const Motion& m = *motions[i];
    const int64_t frames = m.num_frames();
    const auto held = static_cast<int64_t>(std::llround(fraction * static_cast<double>(frames)));
    const int64_t start = validation ? frames - held : 0;
    const int64_t count = validation ? held : frames - held;
    return std::make_tuple(m.poses.data() + start * kNumJoints * 3, m.trans.data() + start * 3,
                           count);
  };
  const size_t n = motions.size();
  const size_t before = tracks_.size();
  for (size_t k = 0; k < n; ++k) {
    const auto [poses, trans, frames] = part(k);
    if (frames < options_.crop) continue;
    const auto partner = part((k + 1) % n);
    if (std::get<2>(partner) > 0) {
      tracks_.push_back({poses, trans, frames, std::get<0>(partner), std::get<2>(partner)});
    } else {
      tracks_.push_back({poses, trans, frames, poses, frames});
    }
  }
  if (tracks_.size() == before)
    throw std::invalid_argument(
        "leg_cleanup: data.motions: no motion has " + std::to_string(options_.crop) +
        " frames or more in its " +
        (validation ? "held-out last " + NumberText(fraction) + " (data.val_fraction)"
                    : std::string("training part")) +
        " at " + NumberText(options_.fps) + " fps (" + std::to_string(files.size()) + " file(s))");
}

plugin::Batch CleanupDataset::Get(const std::vector<int64_t>& indices, uint64_t seed) {
  auto generator = at::make_generator<at::CPUGeneratorImpl>(seed);
  const auto b = static_cast<int64_t>(indices.size());
  const int64_t t = options_.crop;
  // Filled as plain arrays (element-wise tensor indexing would cost more than the step's net).
  std::vector<float> trans_v(static_cast<size_t>(b * t * 3)), r0_v(static_cast<size_t>(b * t * 9));
  const auto legs_n = static_cast<int64_t>(kLegJoints.size());
  std::vector<float> legs_v(static_cast<size_t>(b * t * legs_n * 9)), partner_v(legs_v.size());
  for (int64_t i = 0; i < b; ++i) {
    const Track& track = tracks_.at(static_cast<size_t>(indices[static_cast<size_t>(i)]));
    const int64_t start = torch::randint(0, track.frames - t + 1, {1}, generator).item<int64_t>();
    for (int64_t f = 0; f < t; ++f) {
      const auto at = static_cast<size_t>(i * t + f);
      const float* pose = track.poses + (start + f) * kNumJoints * 3;
      Write(&r0_v[at * 9], pose);
      const float* other =
          track.partner_poses + std::min(start + f, track.partner_frames - 1) * kNumJoints * 3;
      for (size_t k = 0; k < kLegJoints.size(); ++k) {
        Write(&legs_v[(at * kLegJoints.size() + k) * 9], pose + 3 * kLegJoints[k]);
        Write(&partner_v[(at * kLegJoints.size() + k) * 9], other + 3 * kLegJoints[k]);
      }
      const float* x = track.trans + (start + f) * 3;
      for (size_t c = 0; c < 3; ++c) trans_v[at * 3 + c] = x[c];
    }
  }
  const auto trans = torch::from_blob(trans_v.data(), {b, t, 3}).clone();
  const auto r0 = torch::from_blob(r0_v.data(), {b, t, 3, 3}).clone();
  const auto legs = torch::from_blob(legs_v.data(), {b, t, legs_n, 3, 3}).clone();
  const auto partner = torch::from_blob(partner_v.data(), {b, t, legs_n, 3, 3});
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

std::map<std::string, torch::Tensor> CleanupLosses(CleanupNet& net, const Window& window,
                                                   const CleanupOptions& options) {
  auto [cleaned, dz] =
      net->forward(RootFeatures(window.given_trans, window.r0, options.fps), window.noisy);
  cleaned = cleaned.to(torch::kFloat32);
  dz = dz.to(torch::kFloat32);
  std::map<std::string, torch::Tensor> out;
  out["rotation"] = (cleaned - window.legs).pow(2).mean();
  auto corrected = window.given_trans.clone();
  corrected.select(-1, 2).add_(dz);
  const auto p_out = LegPositions(corrected, window.r0, cleaned);
  const auto p_ref = LegPositions(window.trans, window.r0, window.legs);
  out["position"] = (p_out - p_ref).pow(2).sum(-1).mean();
  // Contact where the clean motion's ankle or foot joint stays below the contact height in both
  // frames and moves slower than the skate speed (the evaluation's figures, plausibility.h).
  const PlausibilityOptions plausible;
  const int64_t t = p_ref.size(1);
  const auto horizontal = [](const torch::Tensor& p) { return p.index({Ellipsis, Slice(0, 2)}); };
  const auto step_ref = horizontal(p_ref.narrow(1, 1, t - 1) - p_ref.narrow(1, 0, t - 1));
  const auto speed_ref = step_ref.norm(2, -1) * options.fps;
  const auto z = p_ref.select(-1, 2);
  const auto is_foot = torch::tensor({0.f, 1.f, 1.f, 0.f, 1.f, 1.f});  // knee, ankle, foot per leg
  const auto contact = (z.narrow(1, 1, t - 1) < plausible.contact_height).to(torch::kFloat32) *
                       (z.narrow(1, 0, t - 1) < plausible.contact_height).to(torch::kFloat32) *
                       (speed_ref < plausible.skate_speed).to(torch::kFloat32) * is_foot;
  const auto step_out = horizontal(p_out.narrow(1, 1, t - 1) - p_out.narrow(1, 0, t - 1));
  const auto speed2 = (step_out * options.fps).pow(2).sum(-1);
  out["slide"] = (speed2 * contact).sum() / contact.sum().clamp_min(1);
  out["loss"] = options.rotation_weight * out["rotation"] +
                options.position_weight * out["position"] + options.slide_weight * out["slide"];
  return out;
}

Result<Motion> CleanLegs(CleanupNet& net, const CleanupOptions& options, const Motion& motion) {
  const int64_t frames = motion.num_frames();
  if (frames < 8) return motion;
  if (std::abs(motion.fps - options.fps) > 1e-6) {
    return InvalidArgument("a motion at " + NumberText(motion.fps) +
                           " fps: the leg clean-up was trained at " + NumberText(options.fps));
  }
  torch::NoGradGuard no_grad;
  std::vector<float> rotations(static_cast<size_t>(frames) * (1 + kLegJoints.size()) * 9);
  size_t at = 0;
  const auto put = [&](const Mat3& r) {
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) rotations[at++] = static_cast<float>(r[i][j]);
    }
  };
  for (int64_t f = 0; f < frames; ++f) {
    put(motion.LocalRotation(f, 0));  // the global orientation, then the legs
    for (int joint : kLegJoints) put(motion.LocalRotation(f, joint));
  }
  const auto all = torch::from_blob(rotations.data(),
                                    {1, frames, 1 + static_cast<int64_t>(kLegJoints.size()), 3, 3},
                                    torch::kFloat32);
  const auto r0 = all.select(2, 0);
  const auto legs = all.narrow(2, 1, static_cast<int64_t>(kLegJoints.size()));
  const auto trans =
      torch::from_blob(const_cast<float*>(motion.trans.data()), {1, frames, 3}, torch::kFloat32);
  auto [cleaned, dz] = net->forward(RootFeatures(trans, r0, options.fps), legs);
  cleaned = cleaned.to(torch::kFloat32).contiguous();
  dz = dz.to(torch::kFloat32).contiguous();
  Motion out = motion;
  const float* c = cleaned.data_ptr<float>();
  const float* lift = dz.data_ptr<float>();
  for (int64_t f = 0; f < frames; ++f) {
    for (size_t k = 0; k < kLegJoints.size(); ++k) {
      Mat3 r;
      const float* m =
          c + (f * static_cast<int64_t>(kLegJoints.size()) + static_cast<int64_t>(k)) * 9;
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) r[i][j] = m[i * 3 + j];
      }
      out.SetLocalRotation(f, kLegJoints[k], r);
    }
    if (options.height) out.trans[static_cast<size_t>(f) * 3 + 2] += lift[f];
  }
  for (float v : out.poses) {
    if (!std::isfinite(v)) return Internal("leg clean-up: the model produced NaN");
  }
  return out;
}

}  // namespace motionpipe::legs
