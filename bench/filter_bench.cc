// The similarity filter's throughput (SimMotionEdit sec. 3.2.1) against the NumPy reference
// (bench/reference/similarity_ref.py) on the same triplets in the same run, at MotionFix scale
// (8,000 triplets of ~300 frames from the procedural corpus), and the whole set through
// `motionpipe run` with 1 and 2 workers.
//   filter_bench [--corpus DIR] [--triplets N] [--reference-triplets N] [--locations
//   auto|stored|fk] [--no-run]
#include <omp.h>
#include <sys/wait.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench_util.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/similarity/filter.h"
#include "motionpipe/similarity/similarity.h"

namespace fs = std::filesystem;
using namespace motionpipe;
using namespace motionpipe::similarity;
using bench::Clock;
using bench::Run;
using bench::Since;

namespace {

struct Item {
  const TripletColumns* columns;
  int64_t row;
};

// Seconds to compute every item's similarity with `threads` threads; `kept` counts the kept ones.
double Compute(const std::vector<Item>& items, const SimilarityOptions& options, int threads,
               int64_t* kept) {
  int64_t count = 0;
  const auto start = Clock::now();
#pragma omp parallel num_threads(threads) reduction(+ : count)
  {
    Workspace workspace;
#pragma omp for schedule(dynamic, 4)
    for (size_t k = 0; k < items.size(); ++k) {
      const Item& item = items[k];
      const SimilarityResult r =
          ComputeSimilarity(SideView(item.columns->source, item.row),
                            SideView(item.columns->target, item.row), options, &workspace);
      count += r.kept() ? 1 : 0;
    }
  }
  *kept = count;
  return Since(start);
}

}  // namespace

int main(int argc, char** argv) {
  std::string corpus = "/tmp/motionpipe_filter_bench";
  std::string binary = MOTIONPIPE_BINARY;
  int64_t triplets = 8000, reference_triplets = 400;
  bool run_pipeline = true;
  std::string locations = "auto";
  for (int k = 1; k < argc; ++k) {
    if (!std::strcmp(argv[k], "--corpus") && k + 1 < argc)
      corpus = argv[++k];
    else if (!std::strcmp(argv[k], "--triplets") && k + 1 < argc)
      triplets = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--reference-triplets") && k + 1 < argc)
      reference_triplets = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--no-run"))
      run_pipeline = false;
    else if (!std::strcmp(argv[k], "--locations") && k + 1 < argc)
      locations = argv[++k];
    else {
      std::fprintf(stderr,
                   "usage: filter_bench [--corpus DIR] [--triplets N] [--reference-triplets N] "
                   "[--locations auto|stored|fk] [--no-run]\n");
      return 2;
    }
  }
  if (!fs::exists(corpus + "/manifest.json")) {
    std::printf(
        "generating %lld MotionFix-scale triplets (8-12 s, ~300 frames per motion) into %s ...\n",
        static_cast<long long>(triplets), corpus.c_str());
    std::fflush(stdout);
    Run(binary + " data synth-corpus --clips 100 --triplets " + std::to_string(triplets) +
        " --min-seconds 8 --max-seconds 12 --no-amass --out " + corpus + " 2>&1");
  }
  auto files = ResolveTripletFiles({corpus});
  if (!files.ok()) {
    std::fprintf(stderr, "%s\n", files.status().message().c_str());
    return 1;
  }

  // Load everything first: the comparison is of the computation (both sides start from arrays).
  auto start = Clock::now();
  std::vector<TripletColumns> columns;
  int64_t frames = 0;
  for (const TripletFile& file : *files) {
    auto c = ReadTripletColumns(file.path);
    if (!c.ok()) {
      std::fprintf(stderr, "%s\n", c.status().message().c_str());
      return 1;
    }
    frames += c->source.offsets.back() + c->target.offsets.back();
    columns.push_back(std::move(*c));
  }
  const double load_seconds = Since(start);
  std::vector<Item> all;
  for (const auto& c : columns) {
    for (int64_t row = 0; row < c.rows; ++row) all.push_back({&c, row});
  }
  std::printf(
      "%zu triplets, %lld frames (%.0f per motion) in %zu files; loading (map + CRC check + parse, "
      "2 threads) %.2f s\n",
      all.size(), static_cast<long long>(frames),
      static_cast<double>(frames) / (2.0 * static_cast<double>(all.size())), files->size(),
      load_seconds);

  SimilarityOptions options;  // the paper's constants
  if (locations == "fk") options.locations = LocationSource::kForwardKinematics;
  if (locations == "stored") options.locations = LocationSource::kStored;
  int64_t kept = 0;
  Compute(std::vector<Item>(all.begin(),
                            all.begin() + std::min<int64_t>(200, static_cast<int64_t>(all.size()))),
          options, 1, &kept);  // warm-up
  const double one = Compute(all, options, 1, &kept);
  const double two = Compute(all, options, 2, &kept);
  const double rate_one = static_cast<double>(all.size()) / one,
               rate_two = static_cast<double>(all.size()) / two;
  std::printf("C++ filter, 1 thread : %8.0f triplets/s (%.2f s, %lld kept)\n", rate_one, one,
              static_cast<long long>(kept));
  std::printf("C++ filter, 2 threads: %8.0f triplets/s (%.2f s, speed-up %.2fx)\n", rate_two, two,
              one / two);

  // The same first N triplets through the NumPy reference and through C++ (1 thread).
  const int64_t n = std::min<int64_t>(reference_triplets, static_cast<int64_t>(all.size()));
  std::string file_list;
  for (const auto& f : *files) file_list += " " + f.path;
  const std::string json = Run("/usr/bin/python3 " MOTIONPIPE_SOURCE_DIR
                               "/bench/reference/similarity_ref.py --time --limit " +
                               std::to_string(n) + file_list);
  const size_t at = json.find("\"triplets_per_second\":");
  const double reference_rate = at == std::string::npos ? 0 : std::atof(json.c_str() + at + 22);
  const std::vector<Item> subset(all.begin(), all.begin() + n);
  const double subset_seconds = Compute(subset, options, 1, &kept);
  const double subset_rate = static_cast<double>(n) / subset_seconds;
  std::printf("NumPy reference      : %8.1f triplets/s (first %lld triplets)\n", reference_rate,
              static_cast<long long>(n));
  std::printf("C++, same %lld, 1 thread: %8.0f triplets/s -> %.0fx the reference (goal >= 20x)\n",
              static_cast<long long>(n), subset_rate, subset_rate / reference_rate);

  if (run_pipeline) {
    // The whole set through the engine: coordinator + worker processes, files read, curves and
    // summary written (configs/filter-files.yaml).
    const std::string out = corpus + "-runs";
    for (const int workers : {1, 2}) {
      fs::remove_all(out);
      start = Clock::now();
      Run(binary + " run " MOTIONPIPE_SOURCE_DIR "/configs/filter-files.yaml -q --workers " +
          std::to_string(workers) + " --threads 1 vars.triplets=" + corpus + " output_root=" + out +
          " 2>&1");
      const double seconds = Since(start);
      std::printf(
          "motionpipe run, %d worker(s) x 1 thread: %lld triplets in %.2f s end to end (%.0f "
          "triplets/s; goal < 5 s with 2)\n",
          workers, static_cast<long long>(all.size()), seconds,
          static_cast<double>(all.size()) / seconds);
    }
    fs::remove_all(out);
  }
  return 0;
}
