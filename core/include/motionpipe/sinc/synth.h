// SINC's synthetic training pairs (Synth-Pairs, paper sec. 3.1 and 3.3): two real single actions
// with compatible body parts, composed (composition.h), checked for plausibility, with an augmented
// text (texts.h). A pair is stored as a recipe (~30 bytes), not as motion (~160 KB of features):
// which two spans, which parts, the crop and the text pattern; MaterialisePair makes the same
// motion and text again, bit for bit, for the training loader or an export.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "motionpipe/base/random.h"
#include "motionpipe/base/status.h"
#include "motionpipe/features/temos135.h"
#include "motionpipe/sinc/composition.h"
#include "motionpipe/sinc/spans.h"
#include "motionpipe/sinc/texts.h"

namespace motionpipe::sinc {

inline constexpr char kPairsFormat[] = "motionpipe.sinc-pairs/1";

// Physical checks of a composed motion (the parts of two motions may not fit together): feet that
// slide while in contact, joints below the floor of the leg owner, and sudden jumps of any joint.
struct CompositionChecks {
  double max_skate_ratio = 0.4;   // fraction of contact foot-frames moving faster than 0.15 m/s
  double max_penetration = 0.10;  // m below the floor (the feet's 5th-percentile height)
  double max_joint_step = 0.5;    // m per frame at 30 fps (15 m/s: a glitch, not a sprint)
};

struct CompositionScores {
  float skate_ratio = 0, penetration = 0, max_step = 0;
};

// Scores of a motion (forward kinematics on the SMPL-22 template, vectorised).
CompositionScores ScoreComposition(const Motion& motion);
// Empty when every check passes, else the first failed check's name.
std::string FailedCheck(const CompositionScores& scores, const CompositionChecks& checks);

struct PairRecipe {
  int32_t first = 0, second = 0;  // span indices, in the order they were drawn
  uint8_t first_parts = 0, second_parts = 0;
  uint8_t pattern = 0;       // PairPattern
  uint8_t text_swapped = 0;  // the text names `second` first
  CompositionScores scores;
};

enum class PartSource {
  kLabels,  // the labeler's parts of each action (the paper)
  kRandom,  // random disjoint part sets (the paper's "random composition" ablation)
};

struct SynthOptions {
  uint64_t seed = 1;
  CropMode crop = CropMode::kFirst;
  PartSource parts = PartSource::kLabels;
  std::string split = "train";  // spans of this split only ("" = all)
  CompositionChecks checks;
  int max_attempts_per_pair = 50;  // a shard fails when too few candidates pass the checks
};

Result<SynthOptions> SynthOptionsFromJson(const nlohmann::json& params, const std::string& origin);

// Draws partners: singles are grouped by part set, so a compatible partner (disjoint parts) is a
// draw over the groups weighted by size, then within the group.
class PairSampler {
 public:
  PairSampler(const SpanTable& table, const SynthOptions& options);
  int64_t singles() const { return static_cast<int64_t>(singles_.size()); }
  // A candidate pair (not yet checked); false when the table has no compatible pair at all.
  bool Draw(Rng& rng, PairRecipe* recipe) const;
  // A partner for a given single (the on-the-fly mode of training: a real single is composed with
  // probability p); false when none is compatible.
  bool DrawPartner(int32_t first, Rng& rng, PairRecipe* recipe) const;

 private:
  const SpanTable& table_;
  SynthOptions options_;
  std::vector<int32_t> singles_;                   // span indices
  std::array<std::vector<int32_t>, 64> by_parts_;  // singles per labelled part set
};

// The random-composition ablation's parts for a recipe's two singles: a random part set for the
// first (not every part), a random non-empty subset of the rest for the second.
void DrawRandomParts(Rng& rng, PairRecipe* recipe);

// The composed motion and text of a recipe.
Motion MaterialiseMotion(const SpanTable& table, const PairRecipe& recipe, CropMode crop);
std::string MaterialiseText(const SpanTable& table, const PairRecipe& recipe);
// The 135-d features of the composed motion, straight from the spans (no intermediate motion):
// out[frames * 135], frames = the shorter span's length. Returns the frames.
int64_t MaterialiseFeatures(const SpanTable& table, const PairRecipe& recipe, CropMode crop,
                            float* out);

struct SynthShardReport {
  int64_t pairs = 0, candidates = 0;
  std::map<std::string, int64_t> dropped;  // failed check -> count
  double seconds = 0;
  int64_t bytes = 0;
  int64_t peak_rss_bytes = 0;  // of the process so far
  int64_t rss_bytes = 0;       // resident at the end of the shard
};

// Shard `index` of a synth run: `count` pairs from Rng(MixSeed(seed, index)), checked in parallel
// batches but accepted in draw order, so the bytes do not depend on the thread count. Writes
// pairs.npz (recipes) and stats.json into `out_dir`.
Result<SynthShardReport> SynthesizeShard(const SpanTable& table, const SynthOptions& options,
                                         int64_t index, int64_t count, int threads,
                                         const std::string& out_dir);

// Materialised pairs, numpy-readable. As clips (`motionpipe.clips/1`: motions + the pair text, for
// rendering and BVH export) or as features (`motionpipe.sinc-features/1`: the 135-d TEMOS features
// [F, 135] with offsets, texts, and the recipe columns), what a trainer consumes.
Status ExportPairsAsClips(const SpanTable& table, const std::vector<PairRecipe>& recipes,
                          CropMode crop, const std::string& path);
Status ExportPairsAsFeatures(const SpanTable& table, const std::vector<PairRecipe>& recipes,
                             CropMode crop, const std::string& path, int threads = 1);

struct PairShard {
  std::vector<PairRecipe> recipes;
  CropMode crop = CropMode::kFirst;
  std::string spans;  // the spans file the recipes index (as recorded)
};
Result<PairShard> ReadPairs(const std::string& path);

}  // namespace motionpipe::sinc
