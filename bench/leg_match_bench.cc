// Filling the motion-matching database (`match_legs`, `--match-legs`) from triplet files: the
// sides added one at a time in order (the reference: what the stage and the command line did
// before) against AddTripletSides, which prepares each file's sides (features, leg places) on a
// thread of its own and appends them in the same order, with one thread and with all. Each way's
// database is checked against the reference's by matching the same motions (nearest and random
// windows) to the bit; a figure is the best of --repeat fills.
//
//   leg_match_bench [--triplets N] [--seed S] [--repeat R] [--split SPLIT] [DIR_OR_FILE ...]
//
// Without paths, a procedural corpus of N triplets (shards of 250) is generated into a temporary
// folder and removed; with paths, their triplet files are read as `--match-legs` reads them (a
// stage's directory: its result's, else its tasks').
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "bench_util.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/corpus/corpus.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/motion/leg_match.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {
namespace {

struct Args {
  int64_t triplets = 4000;
  uint64_t seed = 1;
  int repeat = 3;
  std::string split = "train";
  std::vector<std::string> paths;
};

std::string g_folder;  // the generated corpus, removed on the way out

[[noreturn]] void Usage(const std::string& why) {
  if (!g_folder.empty()) std::filesystem::remove_all(g_folder);
  std::fprintf(stderr,
               "leg_match_bench: %s\nusage: leg_match_bench [--triplets N] [--seed S] [--repeat R] "
               "[--split SPLIT] [DIR_OR_FILE ...]\n",
               why.c_str());
  std::exit(2);
}

Args ParseArgs(int argc, char** argv) {
  Args a;
  for (int k = 1; k < argc; ++k) {
    const bool has_value = k + 1 < argc;
    if (!std::strcmp(argv[k], "--triplets") && has_value) {
      a.triplets = std::atoll(argv[++k]);
    } else if (!std::strcmp(argv[k], "--seed") && has_value) {
      a.seed = std::strtoull(argv[++k], nullptr, 10);
    } else if (!std::strcmp(argv[k], "--repeat") && has_value) {
      a.repeat = std::max(1, std::atoi(argv[++k]));
    } else if (!std::strcmp(argv[k], "--split") && has_value) {
      a.split = argv[++k];
    } else if (argv[k][0] == '-') {
      Usage(std::string("unknown option ") + argv[k]);
    } else {
      a.paths.push_back(argv[k]);
    }
  }
  if (a.triplets < 1) Usage("--triplets must be at least 1");
  return a;
}

std::vector<std::string> TripletFilesOf(const std::vector<std::string>& paths) {
  std::vector<std::string> files;
  for (const std::string& path : paths) {
    const std::vector<std::string> some = std::filesystem::is_directory(path)
                                              ? StageTripletFiles(layout::StageOutputDirs(path))
                                              : std::vector<std::string>{path};
    if (some.empty()) Usage(path + ": holds no triplet files");
    files.insert(files.end(), some.begin(), some.end());
  }
  return files;
}

// What a filled database gives the same motions: the matched poses of each, nearest and random.
struct Fingerprint {
  std::vector<float> poses;
  int64_t frames = 0;
  double match_seconds = 0;  // per query, not compared
  bool operator==(const Fingerprint& o) const { return poses == o.poses && frames == o.frames; }
};

Fingerprint Fill(const std::vector<std::string>& files, const std::string& split, bool one_by_one,
                 bool random, const std::vector<Motion>& queries, double* seconds) {
  LegMatchOptions options;
  options.random = random;
  LegDatabase db(Skeleton::Smpl22(), options);
  const auto started = bench::Clock::now();
  if (one_by_one) {
    for (const std::string& file : files) {
      const auto visited = VisitTripletSides(
          file, split, 0,
          [&](const Motion& motion, const std::string& origin) { return db.Add(motion, origin); });
      if (!visited.ok()) Usage(visited.status().message());
    }
  } else {
    const auto added = AddTripletSides(
        files, split, 0, [](const Motion& motion) { return motion; }, &db);
    if (!added.ok()) Usage(added.status().message());
  }
  *seconds = bench::Since(started);
  Fingerprint print;
  print.frames = db.frames();
  const auto matching = bench::Clock::now();
  for (const Motion& query : queries) {
    const auto matched = db.Match(query);
    if (!matched.ok()) Usage(matched.status().message());
    print.poses.insert(print.poses.end(), matched->poses.begin(), matched->poses.end());
  }
  print.match_seconds = bench::Since(matching) / static_cast<double>(queries.size());
  return print;
}

// The first sides of the files as queries (a database window matches itself, so each is taken
// from the middle of a side and is as long as half of it).
std::vector<Motion> Queries(const std::vector<std::string>& files, const std::string& split) {
  std::vector<Motion> queries;
  const auto visited =
      VisitTripletSides(files.front(), split, 4, [&](const Motion& motion, const std::string&) {
        const int64_t T = motion.num_frames();
        queries.push_back(SliceFrames(motion, T / 4, T / 4 + std::max<int64_t>(T / 2, 1)));
        return Status::Ok();
      });
  if (!visited.ok() || queries.empty()) Usage(files.front() + ": no " + split + " triplets");
  return queries;
}

std::string QueryFrames(const std::vector<Motion>& queries) {
  int64_t least = queries.front().num_frames(), most = least;
  for (const Motion& q : queries) {
    least = std::min(least, q.num_frames());
    most = std::max(most, q.num_frames());
  }
  return least == most ? std::to_string(least) : std::to_string(least) + "-" + std::to_string(most);
}

}  // namespace
}  // namespace motionpipe

int main(int argc, char** argv) {
  using namespace motionpipe;
  const Args a = ParseArgs(argc, argv);
  std::string folder;
  std::vector<std::string> paths = a.paths;
  if (paths.empty()) {
    char name[] = "/tmp/leg_match_bench.XXXXXX";
    if (!mkdtemp(name)) Usage("cannot make a temporary folder");
    folder = g_folder = name;
    corpus::CorpusOptions options;
    options.out_dir = folder;
    options.seed = a.seed;
    options.clips = std::max<int64_t>(a.triplets / 4, 50);
    options.triplets = a.triplets;
    options.shard_size = 250;
    options.write_amass = false;
    const auto made = corpus::GenerateCorpus(options);
    if (!made.ok()) Usage(made.status().message());
    paths = {folder};
  }
  const std::vector<std::string> files = TripletFilesOf(paths);
  const std::vector<Motion> queries = Queries(files, a.split);
  const int threads = omp_get_max_threads();
  std::printf("leg database from %zu triplet files (split %s), %d thread(s) at most, best of %d\n",
              files.size(), a.split.c_str(), threads, a.repeat);
  std::printf("%-42s %8s %10s %s\n", "fill", "frames", "seconds", "vs one by one");
  for (const bool random : {false, true}) {
    double reference = 1e30;
    Fingerprint expected;
    for (int r = 0; r < a.repeat; ++r) {
      double s = 0;
      expected = Fill(files, a.split, true, random, queries, &s);
      reference = std::min(reference, s);
    }
    const char* kind = random ? "random" : "nearest";
    std::printf("%-42s %8lld %10.2f %s   (a match: %.3f s a %s-frame query)\n",
                (std::string("one side at a time (") + kind + ")").c_str(),
                static_cast<long long>(expected.frames), reference, "1.00x", expected.match_seconds,
                QueryFrames(queries).c_str());
    std::vector<int> counts = {1};
    if (threads > 1) counts.push_back(threads);
    for (const int n : counts) {
      omp_set_num_threads(n);
      double best = 1e30;
      bool same = true;
      for (int r = 0; r < a.repeat; ++r) {
        double s = 0;
        const bool equal = Fill(files, a.split, false, random, queries, &s) == expected;
        same = same && equal;  // every repeat fills (and is timed), the first difference kept
        best = std::min(best, s);
      }
      omp_set_num_threads(threads);
      std::printf("%-42s %8lld %10.2f %.2fx%s\n",
                  ("AddTripletSides, " + std::to_string(n) + " thread(s) (" + kind + ")").c_str(),
                  static_cast<long long>(expected.frames), best, reference / best,
                  same ? "" : "  MATCHES DIFFER FROM THE REFERENCE'S");
      if (!same) Usage("AddTripletSides filled another database than one side at a time");
    }
  }
  if (!folder.empty()) std::filesystem::remove_all(folder);
  return 0;
}
