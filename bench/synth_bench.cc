// SINC synthetic pairs: composition + re-featurisation (135-d) per second in C++ against the NumPy
// reference (bench/reference/sinc_compose_ref.py) on the same 300-frame motions and recipes in the
// same run, and the synth stage's own rate (composition + plausibility check).
//   synth_bench [--corpus DIR] [--pairs N] [--reference-pairs N]
#include <sys/wait.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "bench_util.h"
#include "motionpipe/features/temos135.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/sinc/spans.h"
#include "motionpipe/sinc/synth.h"

namespace fs = std::filesystem;
using namespace motionpipe;
using bench::Clock;
using bench::Run;
using bench::Since;

namespace {}  // namespace

int main(int argc, char** argv) {
  std::string corpus = "/tmp/motionpipe_synth_bench";
  int64_t pairs = 20000, reference_pairs = 2000;
  for (int k = 1; k < argc; ++k) {
    if (!std::strcmp(argv[k], "--corpus") && k + 1 < argc)
      corpus = argv[++k];
    else if (!std::strcmp(argv[k], "--pairs") && k + 1 < argc)
      pairs = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--reference-pairs") && k + 1 < argc)
      reference_pairs = std::atoll(argv[++k]);
    else {
      std::fprintf(stderr, "usage: synth_bench [--corpus DIR] [--pairs N] [--reference-pairs N]\n");
      return 2;
    }
  }
  if (!fs::exists(corpus + "/manifest.json")) {
    std::printf("generating 400 clips of 10-12 s into %s ...\n", corpus.c_str());
    std::fflush(stdout);
    Run(std::string(MOTIONPIPE_BINARY) +
        " data synth-corpus --clips 400 --triplets 0 --min-seconds 10 --max-seconds 12 --no-amass "
        "--out " +
        corpus + " 2>&1");
  }
  // Spans of exactly 300 frames cut from the corpus clips (the size the issue quotes).
  sinc::SpanTable table;
  for (const auto& entry : fs::directory_iterator(corpus + "/clips")) {
    auto clips = ReadClips(entry.path().string());
    if (!clips.ok()) {
      std::fprintf(stderr, "%s\n", clips.status().message().c_str());
      return 1;
    }
    for (const Clip& clip : *clips) {
      if (clip.motion.num_frames() < 300) continue;
      table.Add(clip.id, "train", clip.source, SliceFrames(clip.motion, 0, 300),
                clip.texts.empty() ? clip.id : clip.texts.front(), "");
    }
  }
  const std::string spans_path = corpus + "/bench_spans.npz";
  if (Status s = sinc::WriteSpans(spans_path, table); !s.ok()) {
    std::fprintf(stderr, "%s\n", s.message().c_str());
    return 1;
  }
  auto mapped = sinc::ReadSpans(spans_path);
  if (!mapped.ok()) return 1;
  std::printf("%lld spans of 300 frames\n", static_cast<long long>(mapped->size()));

  // Recipes: random compatible part sets (every span qualifies), checked as the synth stage does.
  sinc::SynthOptions options;
  options.parts = sinc::PartSource::kRandom;
  const std::string shard_dir = corpus + "/bench_pairs";
  for (const int threads : {1, 2}) {
    const auto t = Clock::now();
    auto report = sinc::SynthesizeShard(*mapped, options, 0, pairs, threads, shard_dir);
    if (!report.ok()) {
      std::fprintf(stderr, "%s\n", report.status().message().c_str());
      return 1;
    }
    std::printf(
        "synth shard (compose + plausibility check), %d thread(s): %8.0f pairs/s (%lld pairs, %lld "
        "candidates)\n",
        threads, static_cast<double>(report->pairs) / Since(t),
        static_cast<long long>(report->pairs), static_cast<long long>(report->candidates));
  }
  auto shard = sinc::ReadPairs(shard_dir + "/pairs.npz");
  if (!shard.ok()) return 1;
  const auto& recipes = shard->recipes;

  // Composition + re-featurisation, one thread, into a reused buffer.
  std::vector<float> buffer(300 * kTemosFeatureDim);
  auto compose_all = [&](size_t n) {
    const auto t = Clock::now();
    double checksum = 0;
    for (size_t k = 0; k < n; ++k) {
      sinc::MaterialiseFeatures(*mapped, recipes[k], shard->crop, buffer.data());
      checksum += buffer[5];
    }
    const double seconds = Since(t);
    if (checksum == 12345.678) std::printf(" ");
    return static_cast<double>(n) / seconds;
  };
  compose_all(std::min<size_t>(500, recipes.size()));  // warm-up
  const double all_rate = compose_all(recipes.size());
  std::printf("C++ compose + featurise, 1 thread: %8.0f pairs/s (%zu pairs)\n", all_rate,
              recipes.size());

  const auto n =
      static_cast<size_t>(std::min<int64_t>(reference_pairs, static_cast<int64_t>(recipes.size())));
  const std::string json =
      Run("/usr/bin/python3 " MOTIONPIPE_SOURCE_DIR
          "/bench/reference/sinc_compose_ref.py --time --limit " +
          std::to_string(n) + " " + spans_path + " " + shard_dir + "/pairs.npz");
  const size_t at = json.find("\"pairs_per_second\":");
  const double reference_rate = at == std::string::npos ? 0 : std::atof(json.c_str() + at + 19);
  const double same_rate = compose_all(n);
  std::printf("NumPy reference:                    %8.0f pairs/s (first %zu pairs)\n",
              reference_rate, n);
  std::printf(
      "C++, the same %zu pairs, 1 thread:  %8.0f pairs/s -> %.1fx the reference (goal >= 10x)\n", n,
      same_rate, same_rate / reference_rate);
  std::printf("a materialised pair: %d frames x 135 float32 = %d bytes; a recipe: %.0f bytes\n",
              300, 300 * kTemosFeatureDim * 4,
              static_cast<double>(fs::file_size(shard_dir + "/pairs.npz")) /
                  static_cast<double>(recipes.size()));
  return 0;
}
