// Training throughput (samples/s) of the TEMOS model (plugins/temos_sinc) at the demo's size and at
// the paper's, against the same architecture in PyTorch Python (bench/reference/temos_ref.py, run
// by Debian's /usr/bin/python3) on the same batch with the same threads, in one run; then the train
// stage's own rate through workers with world_size 1 and 2 (scaling from 1 to 2 ranks). The step is
// also timed under bf16 autocast (plugins/common/precision.h, the train stage's precision: bf16):
// the ratio bf16/f32 of samples/s (--no-bf16: not timed, 0). The float32 step is also given in
// GFLOP/s (its matrix products counted, TrainingStepFlops) beside LibTorch's sgemm rate on the same
// threads, measured in the same run. With --quality, only the time to a retrieval quality
// (tmr_quality.h): the demo's TMR evaluator trained by us and by the PyTorch-Python reference on
// the same stream, checked for test singles' text-to-motion R@1 40 (about 6 min; at the paper's
// size, --quality-size paper, about an hour for 500 steps on one thread; --quality-precision bf16:
// both trainers' forward passes under bf16 autocast, where the CPU has bf16 products).
//   train_bench [--sizes demo,paper] [--steps K] [--threads T] [--batch N] [--frames F]
//               [--no-reference] [--no-scaling] [--no-bf16]
//   train_bench --quality [--spans SPANS.npz] [--quality-size demo|paper (default demo)]
//               [--quality-steps S] [--every E] [--threads T] [--quality-precision float32|bf16]
//               [--no-reference] [--seed S (default 101, the demo's)]
//               [--dir DIR (default /tmp/motionpipe_tmr_quality)]
#include <sys/wait.h>
#include <torch/torch.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "../plugins/common/precision.h"
#include "../plugins/common/threads.h"
#include "../plugins/temos_sinc/temos.h"
#include "bench_util.h"
#include "flops.h"
#include "motionpipe/formats/npy.h"
#include "tmr_quality.h"

namespace fs = std::filesystem;
using namespace motionpipe;
using bench::Clock;
using bench::ExamplesPerSecond;
using bench::LayerMacs;
using bench::QualityArgs;
using bench::Run;
using bench::SgemmGflops;
using bench::Since;
using bench::TemosSize;
using nlohmann::json;

namespace {

// Action texts like the corpus's, to train the tokenizer and fill the batch.
std::vector<std::string> Texts(int64_t n) {
  const char* verbs[] = {"walk forward",    "wave the right hand",
                         "jump in place",   "turn left",
                         "raise both arms", "kick with the left leg",
                         "sit down",        "run in a circle",
                         "clap the hands",  "bow",
                         "crouch",          "step to the side"};
  const char* manners[] = {"slowly", "quickly", "", "twice", "while looking around", "with energy"};
  std::vector<std::string> texts;
  for (int64_t i = 0; i < n; ++i) {
    std::string t = verbs[i % 12];
    const std::string m = manners[(i / 12) % 6];
    if (!m.empty()) t += " " + m;
    texts.push_back(t);
  }
  return texts;
}

struct Args {
  std::string sizes = "demo,paper";
  int64_t steps = 8, threads = 1, batch = 32, frames = 150;
  bool reference = true, scaling = true, quality = false, bf16 = true;
  QualityArgs time_to_quality;
};

std::optional<Args> ParseArgs(int argc, char** argv) {
  Args a;
  for (int k = 1; k < argc; ++k) {
    if (!std::strcmp(argv[k], "--sizes") && k + 1 < argc)
      a.sizes = argv[++k];
    else if (!std::strcmp(argv[k], "--steps") && k + 1 < argc)
      a.steps = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--threads") && k + 1 < argc)
      a.threads = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--batch") && k + 1 < argc)
      a.batch = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--frames") && k + 1 < argc)
      a.frames = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--no-reference"))
      a.reference = false;
    else if (!std::strcmp(argv[k], "--no-scaling"))
      a.scaling = false;
    else if (!std::strcmp(argv[k], "--no-bf16"))
      a.bf16 = false;
    else if (!std::strcmp(argv[k], "--quality"))
      a.quality = true;
    else if (!std::strcmp(argv[k], "--spans") && k + 1 < argc)
      a.time_to_quality.spans = argv[++k];
    else if (!std::strcmp(argv[k], "--quality-size") && k + 1 < argc)
      a.time_to_quality.size = argv[++k];
    else if (!std::strcmp(argv[k], "--quality-precision") && k + 1 < argc &&
             (!std::strcmp(argv[k + 1], "float32") || !std::strcmp(argv[k + 1], "bf16")))
      a.time_to_quality.bf16 = !std::strcmp(argv[++k], "bf16");
    else if (!std::strcmp(argv[k], "--quality-steps") && k + 1 < argc)
      a.time_to_quality.steps = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--every") && k + 1 < argc)
      a.time_to_quality.every = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--seed") && k + 1 < argc)
      a.time_to_quality.seed = std::strtoull(argv[++k], nullptr, 10);
    else if (!std::strcmp(argv[k], "--dir") && k + 1 < argc)
      a.time_to_quality.dir = argv[++k];
    else
      return std::nullopt;
  }
  return a;
}

// The benchmark's batch: lengths between frames/2 and frames, features ~ N(0, 1) (normalised).
struct Batch {
  torch::Tensor features, padding;
};

Batch MakeBatch(const Args& a) {
  std::mt19937 rng(7);
  Batch b;
  b.padding = torch::zeros({a.batch, a.frames}, torch::kBool);
  for (int64_t i = 0; i < a.batch; ++i) {
    const int64_t length =
        a.frames / 2 + static_cast<int64_t>(rng() % static_cast<uint32_t>(a.frames / 2 + 1));
    b.padding[i].narrow(0, length, a.frames - length).fill_(true);
  }
  b.features = torch::randn({a.frames, a.batch, temos::kFeatureDim})
                   .masked_fill(b.padding.t().unsqueeze(2), 0.0);
  return b;
}

// FLOPs of one TEMOS training step, counted from its matrix products: the text encoder and the
// text VAE over the tokens, the motion VAE over the frames (each VAE with its mu and logvar
// tokens), the decoder over the frames for both branches (its cross-attention to one memory token
// is two d x d products per example, left out) and the output layer; forward 2 x multiply-adds,
// backward twice the forward. Padded frames are computed as the step computes them.
double TrainingStepFlops(const TemosSize& size, double batch, double frames, double tokens) {
  const double d = static_cast<double>(size.latent), ff = static_cast<double>(size.ff),
               layers = static_cast<double>(size.layers);
  double macs = LayerMacs(batch, tokens, d, ff) * static_cast<double>(size.text_layers);
  macs += batch * tokens * d * d + LayerMacs(batch, tokens + 2, d, ff) * layers;  // text VAE
  macs += batch * frames * temos::kFeatureDim * d +
          LayerMacs(batch, frames + 2, d, ff) * layers;  // motion VAE
  macs += LayerMacs(2 * batch, frames, d, ff) * layers +
          2 * batch * frames * d * temos::kFeatureDim;  // decoder, both branches
  return 3 * 2 * macs;
}

// The PyTorch-Python reference (bench/reference/temos_ref.py) trained on the same batch: its
// samples per second.
double PythonReference(const Args& a, const TemosSize& size, temos::Temos& net,
                       const std::vector<std::string>& texts, const Batch& b) {
  const std::string dir = "/tmp/motionpipe_train_bench";
  fs::create_directories(dir);
  const auto tokens = net->text_encoder()->TokenIds(texts).contiguous();
  bench::SaveNpy(
      dir + "/tokens.npy",
      NpyArray::Int64({tokens.size(0), tokens.size(1)},
                      std::vector<int64_t>(tokens.data_ptr<int64_t>(),
                                           tokens.data_ptr<int64_t>() + tokens.numel())));
  const auto f = b.features.contiguous();
  bench::SaveNpy(
      dir + "/features.npy",
      NpyArray::Float32({a.frames, a.batch, temos::kFeatureDim},
                        std::vector<float>(f.data_ptr<float>(), f.data_ptr<float>() + f.numel())));
  const auto pad = b.padding.to(torch::kUInt8).contiguous();
  bench::SaveNpy(dir + "/padding.npy",
                 NpyArray::Bool({a.batch, a.frames},
                                std::vector<uint8_t>(pad.data_ptr<uint8_t>(),
                                                     pad.data_ptr<uint8_t>() + pad.numel())));
  std::ostringstream command;
  command << "OMP_NUM_THREADS=" << a.threads << " OPENBLAS_NUM_THREADS=" << a.threads
          << " /usr/bin/python3 " << MOTIONPIPE_SOURCE_DIR
          << "/bench/reference/temos_ref.py --batch-dir " << dir << " --latent " << size.latent
          << " --layers " << size.layers << " --heads " << size.heads << " --ff " << size.ff
          << " --text-layers " << size.text_layers << " --vocab 1000 --steps " << a.steps
          << " --threads " << a.threads;
  const std::string out = Run(command.str());
  return json::parse(out.substr(out.rfind('{'))).at("samples_per_second").get<double>();
}

// One size: our training step's samples per second against the reference's, on the same batch.
void BenchSize(const Args& a, const TemosSize& size) {
  const json config = {
      {"latent", size.latent},
      {"layers", size.layers},
      {"heads", size.heads},
      {"ff", size.ff},
      {"dropout", 0.1},
      {"text_encoder", {{"layers", size.text_layers}, {"vocab", 1000}, {"ff", size.ff}}}};
  torch::manual_seed(1);
  temos::Temos net(temos::TemosOptions::FromJson(config));
  const std::vector<std::string> texts = Texts(a.batch);
  net->text_encoder()->Fit(Texts(72));
  const Batch b = MakeBatch(a);
  std::vector<std::vector<std::string>> groups;
  for (const auto& t : texts) groups.push_back({t});
  int64_t parameters = 0;
  for (const auto& p : net->parameters()) parameters += p.numel();
  torch::optim::AdamW optimizer(net->parameters(),
                                torch::optim::AdamWOptions(1e-4).weight_decay(0.01));
  net->train();
  const auto step = [&](nn::Precision precision) {
    std::map<std::string, torch::Tensor> losses;
    {
      const nn::MixedPrecision autocast(precision);
      losses = net->Losses(groups, b.features, b.padding);
    }
    optimizer.zero_grad();
    losses.at("loss").backward();
    torch::nn::utils::clip_grad_norm_(net->parameters(), 1.0);
    optimizer.step();
    return losses.at("loss").item<double>();
  };
  const auto rate = [&](nn::Precision precision) {
    return ExamplesPerSecond([&] { step(precision); }, a.steps, a.batch);
  };
  const double cpp = rate(nn::Precision::kFloat32), bf16 = a.bf16 ? rate(nn::Precision::kBf16) : 0;
  const double python = a.reference ? PythonReference(a, size, net, texts, b) : 0;
  const double tokens = static_cast<double>(net->text_encoder()->TokenIds(texts).size(1));
  const double achieved = TrainingStepFlops(size, static_cast<double>(a.batch),
                                            static_cast<double>(a.frames), tokens) *
                          cpp / static_cast<double>(a.batch) / 1e9,
               peak = SgemmGflops(size.latent);
  std::printf("%-6s %10lld %12.1f %12.1f %8.2f %11.1f %11.1f %8.0f%% %12.1f %9.2f\n",
              size.name.c_str(), static_cast<long long>(parameters), cpp, python,
              python > 0 ? cpp / python : 0.0, achieved, peak, 100 * achieved / peak, bf16,
              bf16 / cpp);
  std::fflush(stdout);
}

// The train stage through workers, one thread each: 1 rank on 1 worker, then 2 ranks on 2.
void BenchScaling() {
  std::printf(
      "\ntrain stage (SINC, demo size, batch 32, 40 steps, on-the-fly data) through workers, 1 "
      "thread per worker\n");
  std::printf("%-8s %12s %12s %10s\n", "ranks", "samples/s", "wall s", "vs 1 rank");
  const std::string root = "/tmp/motionpipe_train_bench_runs";
  const std::string pipeline = root + ".yaml";
  std::ofstream(pipeline)
      << "name: train_bench\noutput_root: " << root << "\nseed: 1\nvars: {world: 1}\nstages:\n"
      << "  corpus: {kind: corpus, params: {clips: 200, triplets: 0, shard_size: 100}}\n"
      << "  singles: {kind: singles, inputs: [corpus], params: {labeler: lexicon}}\n"
      << "  sinc:\n    kind: train\n    inputs: [singles]\n    world_size: \"${vars.world}\"\n"
      << "    params:\n      model: temos_sinc\n"
      << "      config: {variant: sinc, model: {latent: 128, layers: 2, heads: 4, ff: 512, "
         "text_encoder: {layers: 1, vocab: 800}}}\n"
      << "      data: {synthetic_p: 0.5, max_frames: 150}\n"
      << "      steps: 40\n      batch_size: 32\n      warmup: 5\n      checkpoint_every: 1000\n";
  double one = 0;
  for (int world : {1, 2}) {
    fs::remove_all(root);
    const auto started = Clock::now();
    Run(std::string(MOTIONPIPE_BINARY) + " run " + pipeline + " --workers " +
        std::to_string(world) + " --threads 1 vars.world=" + std::to_string(world) + " 2>&1");
    const double wall = Since(started);
    double total = 0;
    for (const auto& entry : fs::recursive_directory_iterator(root)) {
      const std::string name = entry.path().filename().string();
      if (name.rfind("rank-", 0) == 0 &&
          entry.path().string().find("/sinc/") != std::string::npos) {
        std::ifstream in(entry.path());
        total += json::parse(in).at("samples_per_second").get<double>();
      }
    }
    if (world == 1) one = total;
    std::printf("%-8d %12.1f %12.1f %10.2f\n", world, total, wall, one > 0 ? total / one : 0.0);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const std::string kernels = bench::UseNativeBlasKernels(argv);
  const std::optional<Args> args = ParseArgs(argc, argv);
  if (!args) {
    std::fprintf(stderr,
                 "usage: train_bench [--sizes demo,paper] [--steps K] [--threads T] [--batch N] "
                 "[--frames F] [--no-reference] [--no-scaling] [--no-bf16]\n"
                 "       train_bench --quality [--spans SPANS.npz] [--quality-size demo|paper] "
                 "[--quality-steps S] "
                 "[--every E] [--threads T] [--quality-precision float32|bf16] [--no-reference] "
                 "[--seed S] [--dir DIR]\n");
    return 2;
  }
  if (args->quality) {
    QualityArgs q = args->time_to_quality;
    q.threads = args->threads;
    q.reference = args->reference;
    if (q.steps < 1 || q.every < 1) {
      std::fprintf(stderr, "train_bench: --quality-steps and --every must be at least 1\n");
      return 2;
    }
    bench::BenchTimeToQuality(q);
    return 0;
  }
  nn::SetTorchThreads(static_cast<int>(args->threads));
  std::printf(
      "TEMOS training step (forward, backward, clip, AdamW), batch %lld, up to %lld frames, %lld "
      "thread(s)\n",
      static_cast<long long>(args->batch), static_cast<long long>(args->frames),
      static_cast<long long>(args->threads));
  // The bf16 columns time LibTorch's bf16 products as they are on this CPU; the train stage
  // runs bf16 as float32 where they are emulated (plugins/common/precision.h).
  std::printf("bf16 products on this CPU: %s; OpenBLAS kernels: %s; LibTorch's: %s\n",
              nn::Bf16ProductsOnThisCpu(), kernels.c_str(), nn::AtenCapabilityInUse().c_str());
  std::printf("%-6s %10s %12s %12s %8s %11s %11s %9s %12s %9s\n", "size", "params", "C++ samp/s",
              "Py samp/s", "ratio", "C++ GFLOP/s", "sgemm peak", "of peak", "bf16 samp/s",
              "bf16/f32");
  for (const TemosSize& size : bench::TemosSizes()) {
    if (args->sizes.find(size.name) != std::string::npos) BenchSize(*args, size);
  }
  if (args->scaling) BenchScaling();
  return 0;
}
