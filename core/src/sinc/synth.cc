#include "motionpipe/sinc/synth.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "../simd/simd.h"
#include "motionpipe/base/file.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/npz.h"

namespace motionpipe::sinc {

namespace {

constexpr int kFeet[4] = {7, 10, 8, 11};

int64_t PeakRssBytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<int64_t>(usage.ru_maxrss) * 1024;
}

// Resident memory now (/proc/self/statm), to see whether a worker grows from task to task.
int64_t CurrentRssBytes() {
  FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  long pages = 0, resident = 0;
  const int read = std::fscanf(f, "%ld %ld", &pages, &resident);
  std::fclose(f);
  return read == 2 ? static_cast<int64_t>(resident) * static_cast<int64_t>(sysconf(_SC_PAGESIZE))
                   : 0;
}

// A random non-empty subset of `allowed`.
PartSet RandomSubset(PartSet allowed, Rng& rng) {
  std::vector<int> bits;
  for (int p = 0; p < kNumBodyParts; ++p) {
    if (allowed & (1u << p)) bits.push_back(p);
  }
  if (bits.empty()) return 0;
  PartSet out = 0;
  while (out == 0) {
    for (const int b : bits) {
      if (rng.Bernoulli(0.5)) out |= static_cast<PartSet>(1u << b);
    }
  }
  return out;
}

}  // namespace

CompositionScores ScoreComposition(const Motion& motion) {
  CompositionScores scores;
  const int64_t frames = motion.num_frames();
  if (frames < 2) return scores;
  thread_local std::vector<float> scratch, planes;
  planes.resize(static_cast<size_t>(frames * kNumJoints * 3));
  simd::JointPlanes(motion.poses.data(), motion.trans.data(), frames, &scratch, planes.data());
  auto plane = [&](int j, int a) { return planes.data() + (3 * j + a) * frames; };
  // The floor: the 5th percentile of the lowest foot per frame (feet come with the leg owner).
  std::vector<float> lowest(static_cast<size_t>(frames));
  for (int64_t f = 0; f < frames; ++f) {
    float low = plane(kFeet[0], 2)[f];
    for (const int j : kFeet) low = std::min(low, plane(j, 2)[f]);
    lowest[static_cast<size_t>(f)] = low;
  }
  std::vector<float> sorted = lowest;
  const size_t p5 = static_cast<size_t>(0.05 * static_cast<double>(frames - 1));
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(p5), sorted.end());
  const float floor = sorted[p5];
  float penetration = 0;
  for (int j = 0; j < kNumJoints; ++j) {
    const float* z = plane(j, 2);
    for (int64_t f = 0; f < frames; ++f) penetration = std::max(penetration, floor - z[f]);
  }
  // Skating: feet within 5 cm of the floor in two consecutive frames, moving faster than 0.15 m/s.
  const double fps = motion.fps > 0 ? motion.fps : 30;
  int64_t contacts = 0, skating = 0;
  for (const int j : kFeet) {
    const float *x = plane(j, 0), *y = plane(j, 1), *z = plane(j, 2);
    for (int64_t f = 1; f < frames; ++f) {
      if (z[f] > floor + 0.05f || z[f - 1] > floor + 0.05f) continue;
      ++contacts;
      const double speed = std::hypot(x[f] - x[f - 1], y[f] - y[f - 1]) * fps;
      skating += speed > 0.15 ? 1 : 0;
    }
  }
  float step = 0;
  for (int j = 0; j < kNumJoints; ++j) {
    const float *x = plane(j, 0), *y = plane(j, 1), *z = plane(j, 2);
    for (int64_t f = 1; f < frames; ++f) {
      const float dx = x[f] - x[f - 1], dy = y[f] - y[f - 1], dz = z[f] - z[f - 1];
      step = std::max(step, dx * dx + dy * dy + dz * dz);
    }
  }
  scores.penetration = std::max(0.f, penetration);
  scores.skate_ratio =
      contacts > 0
          ? static_cast<float>(static_cast<double>(skating) / static_cast<double>(contacts))
          : 0.f;
  // Per frame at 30 fps: scale the step of other rates.
  scores.max_step = std::sqrt(step) * static_cast<float>(fps / 30.0);
  return scores;
}

std::string FailedCheck(const CompositionScores& s, const CompositionChecks& c) {
  if (s.skate_ratio > c.max_skate_ratio) return "foot_skate";
  if (s.penetration > c.max_penetration) return "floor_penetration";
  if (s.max_step > c.max_joint_step) return "joint_jump";
  return "";
}

Result<SynthOptions> SynthOptionsFromJson(const nlohmann::json& p, const std::string& origin) {
  SynthOptions o;
  try {
    o.seed = p.value("seed", o.seed);
    MP_ASSIGN_OR_RETURN(o.crop, ParseCropMode(p.value("crop", std::string("first"))));
    const std::string parts = p.value("parts", std::string("labels"));
    if (parts == "labels") {
      o.parts = PartSource::kLabels;
    } else if (parts == "random") {
      o.parts = PartSource::kRandom;
    } else {
      return InvalidArgument(origin + ": parts: '" + parts + "' (known: labels, random)");
    }
    o.split = p.value("split", o.split);
    o.checks.max_skate_ratio = p.value("max_skate_ratio", o.checks.max_skate_ratio);
    o.checks.max_penetration = p.value("max_penetration", o.checks.max_penetration);
    o.checks.max_joint_step = p.value("max_joint_step", o.checks.max_joint_step);
    o.max_attempts_per_pair = p.value("max_attempts_per_pair", o.max_attempts_per_pair);
  } catch (const nlohmann::json::exception& e) {
    return InvalidArgument(origin + ": " + e.what());
  }
  if (o.max_attempts_per_pair < 1)
    return InvalidArgument(origin + ": max_attempts_per_pair must be >= 1");
  return o;
}

PairSampler::PairSampler(const SpanTable& table, const SynthOptions& options)
    : table_(table), options_(options) {
  for (int64_t i = 0; i < table.size(); ++i) {
    if (!table.single(i)) continue;
    if (!options.split.empty() && table.splits[static_cast<size_t>(i)] != options.split) continue;
    const PartSet parts = table.parts_a[static_cast<size_t>(i)] & kAllParts;
    if (options.parts == PartSource::kLabels && parts == 0) continue;
    singles_.push_back(static_cast<int32_t>(i));
    by_parts_[parts].push_back(static_cast<int32_t>(i));
  }
}

bool PairSampler::DrawPartner(int32_t first, Rng& rng, PairRecipe* recipe) const {
  recipe->first = first;
  if (options_.parts == PartSource::kRandom) {
    if (singles_.size() < 2) return false;
    int32_t second = first;
    while (second == first)
      second = singles_[static_cast<size_t>(rng.Int(0, static_cast<int>(singles_.size()) - 1))];
    recipe->second = second;
    DrawRandomParts(rng, recipe);
  } else {
    const PartSet a = table_.parts_a[static_cast<size_t>(first)] & kAllParts;
    std::vector<double> weights(64, 0.0);
    double total = 0;
    for (int b = 1; b < 64; ++b) {
      if (!Compatible(a, static_cast<PartSet>(b))) continue;
      weights[static_cast<size_t>(b)] =
          static_cast<double>(by_parts_[static_cast<size_t>(b)].size());
      total += weights[static_cast<size_t>(b)];
    }
    if (total == 0) return false;
    const auto& group = by_parts_[rng.Weighted(weights)];
    recipe->second = group[static_cast<size_t>(rng.Int(0, static_cast<int>(group.size()) - 1))];
    recipe->first_parts = a;
    recipe->second_parts = table_.parts_a[static_cast<size_t>(recipe->second)] & kAllParts;
  }
  recipe->pattern = static_cast<uint8_t>(rng.Int(0, kNumPairPatterns - 1));
  recipe->text_swapped = rng.Bernoulli(0.5) ? 1 : 0;
  return true;
}

void DrawRandomParts(Rng& rng, PairRecipe* recipe) {
  // A random non-empty part set for the first, then one from the remaining parts for the second.
  PartSet a = RandomSubset(kAllParts, rng);
  while (a == kAllParts) a = RandomSubset(kAllParts, rng);
  recipe->first_parts = a;
  recipe->second_parts = RandomSubset(static_cast<PartSet>(kAllParts & ~a), rng);
}

bool PairSampler::Draw(Rng& rng, PairRecipe* recipe) const {
  if (singles_.empty()) return false;
  // A few tries: a single whose parts leave nothing compatible is redrawn.
  for (int attempt = 0; attempt < 64; ++attempt) {
    const int32_t first =
        singles_[static_cast<size_t>(rng.Int(0, static_cast<int>(singles_.size()) - 1))];
    if (DrawPartner(first, rng, recipe)) return true;
  }
  return false;
}

Motion MaterialiseMotion(const SpanTable& table, const PairRecipe& recipe, CropMode crop) {
  // Views would do; copies keep the composition code simple and the cost is small next to FK.
  thread_local Motion a, b;
  auto fill = [&](int32_t i, Motion* m) {
    const int64_t f0 = table.offsets[static_cast<size_t>(i)],
                  f1 = table.offsets[static_cast<size_t>(i) + 1];
    m->fps = table.fps[static_cast<size_t>(i)];
    m->poses.assign(table.poses + f0 * kNumJoints * 3, table.poses + f1 * kNumJoints * 3);
    m->trans.assign(table.trans + f0 * 3, table.trans + f1 * 3);
  };
  fill(recipe.first, &a);
  fill(recipe.second, &b);
  return Compose(a, recipe.first_parts, b, recipe.second_parts, crop);
}

int64_t MaterialiseFeatures(const SpanTable& table, const PairRecipe& recipe, CropMode crop,
                            float* out) {
  const CompositionPlan plan =
      PlanComposition(table.frames(recipe.first), recipe.first_parts, table.frames(recipe.second),
                      recipe.second_parts, crop);
  const int32_t a = plan.swapped ? recipe.second : recipe.first;
  const int32_t b = plan.swapped ? recipe.first : recipe.second;
  const float* a_poses =
      table.poses + (table.offsets[static_cast<size_t>(a)] + plan.a_start) * kNumJoints * 3;
  const float* b_poses =
      table.poses + (table.offsets[static_cast<size_t>(b)] + plan.b_start) * kNumJoints * 3;
  const float* joints[kNumJoints];
  for (int j = 0; j < kNumJoints; ++j)
    joints[j] = plan.joint_from_b[static_cast<size_t>(j)] ? b_poses : a_poses;
  const float* trans =
      plan.root_from_b ? table.trans + (table.offsets[static_cast<size_t>(b)] + plan.b_start) * 3
                       : table.trans + (table.offsets[static_cast<size_t>(a)] + plan.a_start) * 3;
  EncodeTemos135FastJoints(joints, trans, plan.frames, out);
  return plan.frames;
}

std::string MaterialiseText(const SpanTable& table, const PairRecipe& recipe) {
  const std::string& a = table.text_a[static_cast<size_t>(recipe.first)];
  const std::string& b = table.text_a[static_cast<size_t>(recipe.second)];
  const auto pattern = static_cast<PairPattern>(recipe.pattern % kNumPairPatterns);
  return recipe.text_swapped ? PairText(b, a, pattern) : PairText(a, b, pattern);
}

Result<SynthShardReport> SynthesizeShard(const SpanTable& table, const SynthOptions& options,
                                         int64_t index, int64_t count, int threads,
                                         const std::string& out_dir) {
  const auto started = std::chrono::steady_clock::now();
  SynthShardReport report;
  const PairSampler sampler(table, options);
  if (sampler.singles() < 2) {
    return InvalidArgument("synth: fewer than two labelled single actions in split '" +
                           options.split + "' of the spans table");
  }
  Rng rng(MixSeed(options.seed, static_cast<uint64_t>(index)));
  std::vector<PairRecipe> accepted;
  accepted.reserve(static_cast<size_t>(count));
  const int64_t batch = 256;
  const int64_t max_candidates = count * options.max_attempts_per_pair;
  while (static_cast<int64_t>(accepted.size()) < count) {
    if (report.candidates >= max_candidates) {
      return Internal("synth: only " + std::to_string(accepted.size()) + " of " +
                      std::to_string(count) + " pairs passed the checks after " +
                      std::to_string(report.candidates) +
                      " candidates; loosen the checks or check the spans");
    }
    // Draw a batch in order, check it in parallel, accept in draw order.
    std::vector<PairRecipe> candidates(static_cast<size_t>(batch));
    for (auto& c : candidates) {
      if (!sampler.Draw(rng, &c))
        return InvalidArgument("synth: no two single actions have compatible body parts");
    }
    std::vector<std::string> failed(candidates.size());
#pragma omp parallel for schedule(dynamic, 8) num_threads(std::max(1, threads))
    for (int64_t k = 0; k < batch; ++k) {
      PairRecipe& c = candidates[static_cast<size_t>(k)];
      c.scores = ScoreComposition(MaterialiseMotion(table, c, options.crop));
      failed[static_cast<size_t>(k)] = FailedCheck(c.scores, options.checks);
    }
    for (size_t k = 0; k < candidates.size() && static_cast<int64_t>(accepted.size()) < count;
         ++k) {
      ++report.candidates;
      if (!failed[k].empty()) {
        ++report.dropped[failed[k]];
        continue;
      }
      accepted.push_back(candidates[k]);
    }
  }
  report.pairs = static_cast<int64_t>(accepted.size());

  MP_RETURN_IF_ERROR(MakeDirs(out_dir));
  const auto n = static_cast<int64_t>(accepted.size());
  std::vector<int32_t> first, second;
  std::vector<uint8_t> first_parts, second_parts, pattern, swapped;
  std::vector<float> skate, penetration, step;
  for (const PairRecipe& r : accepted) {
    first.push_back(r.first);
    second.push_back(r.second);
    first_parts.push_back(r.first_parts);
    second_parts.push_back(r.second_parts);
    pattern.push_back(r.pattern);
    swapped.push_back(r.text_swapped);
    skate.push_back(r.scores.skate_ratio);
    penetration.push_back(r.scores.penetration);
    step.push_back(r.scores.max_step);
  }
  Npz npz;
  npz.Add("format", NpyArray::ScalarString(kPairsFormat));
  npz.Add("crop", NpyArray::ScalarString(CropModeName(options.crop)));
  npz.Add("first", NpyArray::Int32({n}, first));
  npz.Add("second", NpyArray::Int32({n}, second));
  npz.Add("first_parts", NpyArray::UInt8({n}, first_parts));
  npz.Add("second_parts", NpyArray::UInt8({n}, second_parts));
  npz.Add("pattern", NpyArray::UInt8({n}, pattern));
  npz.Add("text_swapped", NpyArray::UInt8({n}, swapped));
  npz.Add("skate_ratio", NpyArray::Float32({n}, skate));
  npz.Add("penetration", NpyArray::Float32({n}, penetration));
  npz.Add("max_step", NpyArray::Float32({n}, step));
  const std::string bytes = SerializeNpz(npz, false);
  MP_RETURN_IF_ERROR(WriteFileAtomic(out_dir + "/pairs.npz", bytes, false));
  report.bytes = static_cast<int64_t>(bytes.size());
  report.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  report.peak_rss_bytes = PeakRssBytes();
  report.rss_bytes = CurrentRssBytes();
  const nlohmann::json stats = {
      {"index", index},
      {"pairs", report.pairs},
      {"candidates", report.candidates},
      {"dropped", report.dropped},
      {"seconds", report.seconds},
      {"bytes", report.bytes},
      {"peak_rss_bytes", report.peak_rss_bytes},
      {"rss_bytes", report.rss_bytes},
      {"pid", static_cast<int64_t>(::getpid())},
      {"singles", sampler.singles()},
      {"parts", options.parts == PartSource::kLabels ? "labels" : "random"},
      {"crop", CropModeName(options.crop)},
      {"seed", options.seed}};
  MP_RETURN_IF_ERROR(WriteFileAtomic(out_dir + "/stats.json", stats.dump(1) + "\n", false));
  return report;
}

Status ExportPairsAsClips(const SpanTable& table, const std::vector<PairRecipe>& recipes,
                          CropMode crop, const std::string& path) {
  std::vector<Clip> clips;
  for (size_t k = 0; k < recipes.size(); ++k) {
    const PairRecipe& r = recipes[k];
    Clip clip;
    clip.id = "pair" + std::to_string(k);
    clip.source = "sinc:" + table.ids[static_cast<size_t>(r.first)] + "+" +
                  table.ids[static_cast<size_t>(r.second)];
    clip.motion = MaterialiseMotion(table, r, crop);
    clip.texts = {MaterialiseText(table, r)};
    CompositionPlan plan = PlanComposition(table.frames(r.first), r.first_parts,
                                           table.frames(r.second), r.second_parts, crop);
    Segment a, b;
    a.start_frame = b.start_frame = 0;
    a.end_frame = b.end_frame = static_cast<int32_t>(plan.frames);
    a.text = table.text_a[static_cast<size_t>(r.first)];
    a.parts = r.first_parts;
    b.text = table.text_a[static_cast<size_t>(r.second)];
    b.parts = r.second_parts;
    clip.segments = {a, b};
    clips.push_back(std::move(clip));
  }
  return WriteClips(path, clips, false);
}

Status ExportPairsAsFeatures(const SpanTable& table, const std::vector<PairRecipe>& recipes,
                             CropMode crop, const std::string& path, int threads) {
  const auto n = static_cast<int64_t>(recipes.size());
  std::vector<int64_t> offsets(static_cast<size_t>(n) + 1, 0);
  for (int64_t k = 0; k < n; ++k) {
    const PairRecipe& r = recipes[static_cast<size_t>(k)];
    offsets[static_cast<size_t>(k) + 1] =
        offsets[static_cast<size_t>(k)] + std::min(table.frames(r.first), table.frames(r.second));
  }
  std::vector<float> features(static_cast<size_t>(offsets.back() * kTemosFeatureDim));
#pragma omp parallel for schedule(dynamic, 16) num_threads(std::max(1, threads))
  for (int64_t k = 0; k < n; ++k) {
    MaterialiseFeatures(table, recipes[static_cast<size_t>(k)], crop,
                        features.data() + offsets[static_cast<size_t>(k)] * kTemosFeatureDim);
  }
  std::vector<std::string> texts;
  std::vector<int32_t> first, second;
  std::vector<uint8_t> first_parts, second_parts;
  for (const PairRecipe& r : recipes) {
    texts.push_back(MaterialiseText(table, r));
    first.push_back(r.first);
    second.push_back(r.second);
    first_parts.push_back(r.first_parts);
    second_parts.push_back(r.second_parts);
  }
  Npz npz;
  npz.Add("format", NpyArray::ScalarString("motionpipe.sinc-features/1"));
  npz.Add("offsets", NpyArray::Int64({n + 1}, offsets));
  npz.Add("features", NpyArray::Float32({offsets.back(), kTemosFeatureDim}, features));
  npz.Add("texts", NpyArray::Strings({n}, texts));
  npz.Add("first", NpyArray::Int32({n}, first));
  npz.Add("second", NpyArray::Int32({n}, second));
  npz.Add("first_parts", NpyArray::UInt8({n}, first_parts));
  npz.Add("second_parts", NpyArray::UInt8({n}, second_parts));
  return WriteNpz(path, npz, false);
}

Result<PairShard> ReadPairs(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const Npz npz, ReadNpz(path));
  MP_ASSIGN_OR_RETURN(const NpyArray* format, GetShaped(npz, "format", {}, path));
  MP_ASSIGN_OR_RETURN(auto format_text, format->ToStrings(path));
  if (format_text.front() != kPairsFormat)
    return DataLoss(path + ": format is '" + format_text.front() + "', expected '" + kPairsFormat +
                    "'");
  PairShard shard;
  MP_ASSIGN_OR_RETURN(const NpyArray* crop, GetShaped(npz, "crop", {}, path));
  MP_ASSIGN_OR_RETURN(auto crop_text, crop->ToStrings(path));
  MP_ASSIGN_OR_RETURN(shard.crop, ParseCropMode(crop_text.front()));
  MP_ASSIGN_OR_RETURN(const NpyArray* first, GetShaped(npz, "first", {-1}, path));
  const int64_t n = first->shape[0];
  auto ints = [&](const char* name) -> Result<std::vector<int64_t>> {
    MP_ASSIGN_OR_RETURN(const NpyArray* a, GetShaped(npz, name, {n}, path));
    return a->ToInt64(path + ": '" + name + "'");
  };
  auto floats = [&](const char* name) -> Result<std::vector<float>> {
    MP_ASSIGN_OR_RETURN(const NpyArray* a, GetShaped(npz, name, {n}, path));
    return a->ToFloat32(path + ": '" + name + "'");
  };
  MP_ASSIGN_OR_RETURN(auto f, ints("first"));
  MP_ASSIGN_OR_RETURN(auto s, ints("second"));
  MP_ASSIGN_OR_RETURN(auto fp, ints("first_parts"));
  MP_ASSIGN_OR_RETURN(auto sp, ints("second_parts"));
  MP_ASSIGN_OR_RETURN(auto pat, ints("pattern"));
  MP_ASSIGN_OR_RETURN(auto sw, ints("text_swapped"));
  MP_ASSIGN_OR_RETURN(auto sk, floats("skate_ratio"));
  MP_ASSIGN_OR_RETURN(auto pe, floats("penetration"));
  MP_ASSIGN_OR_RETURN(auto st, floats("max_step"));
  shard.recipes.resize(static_cast<size_t>(n));
  for (size_t k = 0; k < shard.recipes.size(); ++k) {
    PairRecipe& r = shard.recipes[k];
    r.first = static_cast<int32_t>(f[k]);
    r.second = static_cast<int32_t>(s[k]);
    r.first_parts = static_cast<uint8_t>(fp[k]);
    r.second_parts = static_cast<uint8_t>(sp[k]);
    r.pattern = static_cast<uint8_t>(pat[k]);
    r.text_swapped = static_cast<uint8_t>(sw[k]);
    r.scores = {sk[k], pe[k], st[k]};
  }
  return shard;
}

}  // namespace motionpipe::sinc
