// Corpus generation throughput: clips and triplets per second with 1 and 2 threads on the same
// seed (identical output), and optionally a MotionFix-scale set (8,000 triplets of ~10 s).
//   corpus_bench [--clips N] [--triplets N] [--motionfix-scale] [--out DIR]
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>

#include "motionpipe/corpus/corpus.h"

using motionpipe::corpus::CorpusOptions;
using motionpipe::corpus::GenerateCorpus;

namespace {
double Run(CorpusOptions options, const char* what) {
  std::filesystem::remove_all(options.out_dir);
  const auto start = std::chrono::steady_clock::now();
  auto summary = GenerateCorpus(options);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!summary.ok()) {
    std::fprintf(stderr, "%s\n", summary.status().ToString().c_str());
    std::exit(1);
  }
  std::printf(
      "%-34s %6lld clips + %6lld triplets (%8lld frames) in %7.2f s: %7.1f clips/s, %7.1f "
      "triplets/s, %9.0f frames/s, %lld resampled\n",
      what, static_cast<long long>(summary->clips), static_cast<long long>(summary->triplets),
      static_cast<long long>(summary->frames + summary->triplet_frames), seconds,
      static_cast<double>(summary->clips) / seconds,
      static_cast<double>(summary->triplets) / seconds,
      static_cast<double>(summary->frames + summary->triplet_frames) / seconds,
      static_cast<long long>(summary->rejected));
  return seconds;
}
}  // namespace

int main(int argc, char** argv) {
  CorpusOptions options;
  options.out_dir = "/tmp/motionpipe_corpus_bench";
  options.clips = 1500;
  options.triplets = 1500;
  bool motionfix_scale = false;
  for (int k = 1; k < argc; ++k) {
    if (!std::strcmp(argv[k], "--clips") && k + 1 < argc)
      options.clips = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--triplets") && k + 1 < argc)
      options.triplets = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--out") && k + 1 < argc)
      options.out_dir = argv[++k];
    else if (!std::strcmp(argv[k], "--motionfix-scale"))
      motionfix_scale = true;
  }
  options.threads = 1;
  const double one = Run(options, "demo size, 1 thread");
  options.threads = 2;
  const double two = Run(options, "demo size, 2 threads");
  std::printf(
      "speed-up with 2 threads: %.2fx (output identical: the manifest lists sha256 of every "
      "file)\n",
      one / two);
  if (motionfix_scale) {
    // MotionFix: ~8,000 triplets of ~300 frames. Clips of 8-12 s give ~300 frames per motion.
    options.clips = 1;
    options.triplets = 8000;
    options.script.min_seconds = 8;
    options.script.max_seconds = 12;
    options.write_amass = false;
    Run(options, "MotionFix scale, 2 threads");
  }
  std::filesystem::remove_all(options.out_dir);
  return 0;
}
